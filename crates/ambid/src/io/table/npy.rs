//! NumPy `.npy` (one array) and `.npz` (a zip archive of `.npy` members, stored or deflated),
//! read with the `npyz` crate; the archive is opened with the `zip` crate.

use std::io::Read;
use std::path::Path;

use npyz::{NpyFile, TypeChar};

use super::arrays::{assemble, too_big, Order, Var, MAX_DECODED_BYTES};
use super::{DataFileError, ReadOptions, Table};

const RESAVE: &str = "save it again with numpy.save / numpy.savez";

pub(super) fn read_npy(path: &Path, _opts: &ReadOptions) -> Result<Table, DataFileError> {
    let file = std::fs::File::open(path).map_err(|e| DataFileError::open(path, &e))?;
    let size = file.metadata().map(|m| m.len()).unwrap_or(u64::MAX);
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "x".to_string());
    let var = read_array(std::io::BufReader::new(file), name, size)
        .map_err(|m| DataFileError::invalid(path, m))?;
    assemble(path, vec![var], None)
}

pub(super) fn read_npz(path: &Path, opts: &ReadOptions) -> Result<Table, DataFileError> {
    let file = std::fs::File::open(path).map_err(|e| DataFileError::open(path, &e))?;
    let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file)).map_err(|e| {
        DataFileError::invalid(
            path,
            format!("is not a readable .npz (zip) archive ({e}); {RESAVE}"),
        )
    })?;
    let mut vars = Vec::new();
    let mut decoded = 0u64;
    for i in 0..zip.len() {
        let entry = zip.by_index(i).map_err(|e| {
            DataFileError::invalid(
                path,
                format!("has a member that cannot be read ({e}); {RESAVE} (without encryption or unusual compression)"),
            )
        })?;
        if entry.is_dir() {
            continue;
        }
        let member = entry.name().to_string();
        let name = member.strip_suffix(".npy").unwrap_or(&member).to_string();
        if let Some(want) = opts.variable.as_deref() {
            if want != name {
                vars.push(Var::Unusable {
                    name,
                    reason: "not selected".into(),
                });
                continue;
            }
        }
        let size = entry.size();
        // the size the zip directory declares, checked before anything is inflated; the
        // stream is cut there as well, so a member cannot inflate past what it declares
        if size > MAX_DECODED_BYTES {
            return Err(DataFileError::invalid(
                path,
                format!(
                    "variable `{name}`: {}",
                    too_big("the decompressed member", size)
                ),
            ));
        }
        decoded = decoded.saturating_add(size);
        if decoded > MAX_DECODED_BYTES {
            return Err(DataFileError::invalid(
                path,
                too_big("the decompressed members together", decoded),
            ));
        }
        let var = read_array(entry.take(size), name.clone(), size)
            .map_err(|m| DataFileError::invalid(path, format!("variable `{name}`: {m}")))?;
        vars.push(var);
    }
    assemble(path, vars, opts.variable.as_deref())
}

/// Reads the `.npy` preamble (magic, version, header length, header text) and checks that the
/// shape's element count does not overflow (npyz multiplies the dimensions unchecked). Returns
/// the bytes read, to be put back in front of the stream.
fn check_preamble<R: Read>(reader: &mut R) -> Result<Vec<u8>, String> {
    let not_npy = || format!("is not a readable .npy array (bad header); {RESAVE}");
    let mut pre = [0u8; 10];
    reader.read_exact(&mut pre).map_err(|_| not_npy())?;
    let [0x93, b'N', b'U', b'M', b'P', b'Y', major, _, l0, l1] = pre else {
        return Err(not_npy());
    };
    let mut out = pre.to_vec();
    let len = match major {
        1 => usize::from(u16::from_le_bytes([l0, l1])),
        2 | 3 => {
            let mut more = [0u8; 2];
            reader.read_exact(&mut more).map_err(|_| not_npy())?;
            out.extend_from_slice(&more);
            u32::from_le_bytes([l0, l1, more[0], more[1]]) as usize
        }
        _ => return Err(not_npy()),
    };
    if len > 1 << 20 {
        return Err(not_npy());
    }
    let mut header = vec![0u8; len];
    reader.read_exact(&mut header).map_err(|_| not_npy())?;
    let text = String::from_utf8_lossy(&header);
    if let Some(tuple) = text
        .split_once("'shape'")
        .and_then(|(_, rest)| rest.split_once('('))
        .and_then(|(_, rest)| rest.split_once(')'))
        .map(|(tuple, _)| tuple)
    {
        let mut total: Option<u64> = Some(1);
        for d in tuple.split(',').map(str::trim).filter(|d| !d.is_empty()) {
            let d: u64 = d.trim_end_matches('L').parse().map_err(|_| not_npy())?;
            total = total.and_then(|t| t.checked_mul(d));
        }
        if total.is_none() {
            return Err(format!(
                "claims a shape ({tuple}) with more elements than can exist; the file is damaged; {RESAVE}"
            ));
        }
    }
    out.extend_from_slice(&header);
    Ok(out)
}

/// Reads one `.npy` stream of at most `size` bytes into a variable.
fn read_array<R: Read>(mut reader: R, name: String, size: u64) -> Result<Var, String> {
    let pre = check_preamble(&mut reader)?;
    let reader = std::io::Cursor::new(pre).chain(reader);
    let npy = NpyFile::new(reader)
        .map_err(|e| format!("is not a readable .npy array ({e}); {RESAVE}"))?;
    let shape: Vec<usize> = npy
        .shape()
        .iter()
        .map(|&d| usize::try_from(d).unwrap_or(usize::MAX))
        .collect();
    let order = match npy.order() {
        npyz::Order::C => Order::RowMajor,
        npyz::Order::Fortran => Order::ColumnMajor,
    };
    let dtype = npy.dtype();
    let npyz::DType::Plain(ts) = &dtype else {
        return Ok(Var::Unusable {
            name,
            reason: format!(
                "has the structured dtype {}; save plain numeric arrays",
                dtype.descr()
            ),
        });
    };
    let item = ts.size_field();
    // A damaged header must not make us allocate more than the file can hold.
    let claimed = npy.len().saturating_mul(item);
    if claimed > size {
        return Err(format!(
            "claims {} values of {item} bytes but the data are only {size} bytes; the file is truncated or damaged; {RESAVE}",
            npy.len()
        ));
    }
    // as f64, the values take 8 bytes each whatever their stored type
    let as_f64 = (npy.len()).saturating_mul(8);
    if as_f64 > MAX_DECODED_BYTES {
        return Err(too_big(
            &format!("the array of {} values", npy.len()),
            as_f64,
        ));
    }
    let err = |e: std::io::Error| {
        format!("cannot read its values ({e}); the file is truncated or damaged; {RESAVE}")
    };
    let data: Vec<f64> = match (ts.type_char(), item) {
        (TypeChar::Float, 8) => npy.into_vec::<f64>().map_err(err)?,
        (TypeChar::Float, 4) => to_f64(npy.into_vec::<f32>().map_err(err)?),
        (TypeChar::Int, 1) => to_f64(npy.into_vec::<i8>().map_err(err)?),
        (TypeChar::Int, 2) => to_f64(npy.into_vec::<i16>().map_err(err)?),
        (TypeChar::Int, 4) => to_f64(npy.into_vec::<i32>().map_err(err)?),
        (TypeChar::Int, 8) => npy
            .into_vec::<i64>()
            .map_err(err)?
            .into_iter()
            .map(|v| v as f64)
            .collect(),
        (TypeChar::Uint, 1) => to_f64(npy.into_vec::<u8>().map_err(err)?),
        (TypeChar::Uint, 2) => to_f64(npy.into_vec::<u16>().map_err(err)?),
        (TypeChar::Uint, 4) => to_f64(npy.into_vec::<u32>().map_err(err)?),
        (TypeChar::Uint, 8) => npy
            .into_vec::<u64>()
            .map_err(err)?
            .into_iter()
            .map(|v| v as f64)
            .collect(),
        (TypeChar::Bool, 1) => npy
            .into_vec::<bool>()
            .map_err(err)?
            .into_iter()
            .map(|v| if v { 1.0 } else { 0.0 })
            .collect(),
        _ => {
            return Ok(Var::Unusable {
                name,
                reason: format!(
                    "has dtype {ts}, which is not a real number type; save it as float64"
                ),
            })
        }
    };
    Ok(Var::Numeric {
        name,
        shape,
        order,
        data,
    })
}

fn to_f64<T: Into<f64>>(v: Vec<T>) -> Vec<f64> {
    v.into_iter().map(Into::into).collect()
}
