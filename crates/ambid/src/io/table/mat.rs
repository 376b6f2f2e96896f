//! MATLAB MAT-file version 5 (also what MATLAB's `-v6` and `-v7` write): a 128-byte header,
//! then data elements (tag: type and byte count, data padded to 8 bytes, or a "small element"
//! with up to 4 bytes inside the tag). Variables are `miMATRIX` elements, possibly inside
//! zlib-compressed `miCOMPRESSED` elements. Only the parts needed for numeric arrays are
//! interpreted: array flags (class, complex), dimensions, name and real part. Everything is
//! bounds-checked; a damaged file gives an error, never a panic.
//!
//! v7.3 files are HDF5 and are read by the sibling module `mat73`.

use std::io::Read;
use std::path::Path;

use super::arrays::{assemble, too_big, Order, Var, MAX_DECODED_BYTES};
use super::{DataFileError, ReadOptions, Table};

// Data types (MAT-file format reference, table "MAT-File Data Types").
const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_INT64: u32 = 12;
const MI_UINT64: u32 = 13;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;

// Array classes (array flags, low byte).
const MX_CELL: u8 = 1;
const MX_STRUCT: u8 = 2;
const MX_OBJECT: u8 = 3;
const MX_CHAR: u8 = 4;
const MX_SPARSE: u8 = 5;
const MX_DOUBLE: u8 = 6;
const MX_UINT64: u8 = 15;
const FLAG_COMPLEX: u32 = 0x0800;

/// Limit on the decompressed size of one compressed variable and on the file itself: the
/// shared [`MAX_DECODED_BYTES`] (512 MiB), checked against the length the compressed element's
/// own tag declares before it is inflated.
const MAX_DECOMPRESSED: u64 = MAX_DECODED_BYTES;

pub(super) fn read(path: &Path, opts: &ReadOptions) -> Result<Table, DataFileError> {
    let size = std::fs::metadata(path)
        .map_err(|e| DataFileError::open(path, &e))?
        .len();
    if size > MAX_DECOMPRESSED {
        return Err(DataFileError::invalid(path, too_big("the file", size)));
    }
    let bytes = std::fs::read(path).map_err(|e| DataFileError::open(path, &e))?;
    let vars = parse(&bytes).map_err(|e| match e {
        // read_table sends v7.3 files to the HDF5 reader before this one
        MatError::V73 => DataFileError::invalid(
            path,
            "a MATLAB v7.3 (HDF5) MAT-file: read it through read_table (format `mat`), which detects the version",
        ),
        MatError::Bad(m) => DataFileError::invalid(path, m),
    })?;
    assemble(path, vars, opts.variable.as_deref())
}

#[derive(Debug)]
enum MatError {
    V73,
    Bad(String),
}

fn bad(msg: impl Into<String>) -> MatError {
    MatError::Bad(msg.into())
}

const RESAVE: &str = "save it again from MATLAB with `-v7`, or export the signals to CSV";

/// Parses the whole file into variables (in file order).
fn parse(bytes: &[u8]) -> Result<Vec<Var>, MatError> {
    if bytes.starts_with(b"MATLAB 7.3 MAT-file")
        || bytes.get(512..520) == Some(b"\x89HDF\r\n\x1a\n")
    {
        return Err(MatError::V73);
    }
    let Some(header) = bytes.get(..128) else {
        return Err(bad(format!(
            "is too short ({} bytes) to be a MAT-file; {RESAVE}",
            bytes.len()
        )));
    };
    let big = match header.get(126..128) {
        Some(b"IM") => false,
        Some(b"MI") => true,
        _ => {
            return Err(bad(format!(
                "is not a MAT-file of version 5 or later (no `MATLAB 5.0 MAT-file` header; a v4 file?); {RESAVE}"
            )))
        }
    };
    let version = Endian { big }.u16(header.get(124..126).unwrap_or(&[0, 0]));
    if version == 0x0200 {
        return Err(MatError::V73);
    }
    let mut vars = Vec::new();
    parse_elements(
        bytes.get(128..).unwrap_or(&[]),
        Endian { big },
        0,
        &mut vars,
    )?;
    Ok(vars)
}

#[derive(Clone, Copy)]
struct Endian {
    big: bool,
}

impl Endian {
    fn u16(self, b: &[u8]) -> u16 {
        let a = [
            b.first().copied().unwrap_or(0),
            b.get(1).copied().unwrap_or(0),
        ];
        if self.big {
            u16::from_be_bytes(a)
        } else {
            u16::from_le_bytes(a)
        }
    }

    fn u32(self, b: &[u8]) -> u32 {
        let mut a = [0u8; 4];
        for (d, s) in a.iter_mut().zip(b) {
            *d = *s;
        }
        if self.big {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        }
    }
}

/// One data element: its type and its data bytes.
struct Element<'a> {
    kind: u32,
    data: &'a [u8],
}

/// Splits `buf` into data elements.
fn elements(buf: &[u8], e: Endian) -> Result<Vec<Element<'_>>, MatError> {
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < buf.len() {
        let Some(tag) = buf.get(pos..pos + 8) else {
            // Trailing padding shorter than a tag.
            if buf
                .get(pos..)
                .is_some_and(|rest| rest.iter().all(|&b| b == 0))
            {
                break;
            }
            return Err(bad(format!(
                "is truncated or damaged (an element tag at byte {pos} is cut off); {RESAVE}"
            )));
        };
        let first = e.u32(&tag[..4]);
        if first >> 16 != 0 {
            // Small data element: type in the low, byte count in the high 16 bits.
            let kind = first & 0xffff;
            let n = (first >> 16) as usize;
            if n > 4 {
                return Err(bad(format!(
                    "is damaged (a small element at byte {pos} claims {n} bytes); {RESAVE}"
                )));
            }
            out.push(Element {
                kind,
                data: &tag[4..4 + n],
            });
            pos += 8;
            continue;
        }
        let kind = first;
        let n = e.u32(&tag[4..8]) as usize;
        let start = pos + 8;
        let Some(data) = start.checked_add(n).and_then(|end| buf.get(start..end)) else {
            return Err(bad(format!(
                "is truncated or damaged (an element at byte {pos} claims {n} bytes, only {} remain); {RESAVE}",
                buf.len().saturating_sub(start)
            )));
        };
        out.push(Element { kind, data });
        // Compressed elements are not padded; all others are padded to a multiple of 8 bytes.
        let padded = if kind == MI_COMPRESSED {
            n
        } else {
            n.div_ceil(8) * 8
        };
        pos = start.saturating_add(padded);
    }
    Ok(out)
}

/// Parses the top-level elements (variables) of `buf` into `vars`.
fn parse_elements(
    buf: &[u8],
    e: Endian,
    depth: usize,
    vars: &mut Vec<Var>,
) -> Result<(), MatError> {
    for el in elements(buf, e)? {
        match el.kind {
            MI_MATRIX => {
                if let Some(v) = parse_matrix(el.data, e)? {
                    vars.push(v);
                }
            }
            MI_COMPRESSED if depth == 0 => {
                let inner = inflate(el.data, e)?;
                parse_elements(&inner, e, depth + 1, vars)?;
            }
            // Other top-level elements carry no variables.
            _ => {}
        }
    }
    Ok(())
}

/// Inflates one `miCOMPRESSED` element. The inflated data start with the tag of the element
/// they hold (type, byte count); that count is checked against [`MAX_DECOMPRESSED`] before the
/// rest is inflated, and inflation stops at the declared size.
fn inflate(data: &[u8], e: Endian) -> Result<Vec<u8>, MatError> {
    let damaged = |err: std::io::Error| {
        bad(format!(
            "has a damaged compressed variable ({err}); {RESAVE}"
        ))
    };
    let mut z = flate2::read::ZlibDecoder::new(data);
    let mut tag = [0u8; 8];
    let mut got = 0;
    while got < tag.len() {
        match z.read(&mut tag[got..]).map_err(damaged)? {
            0 => break,
            k => got += k,
        }
    }
    let tag = &tag[..got];
    // a small-element tag (byte count in the upper half of the first word) holds ≤ 4 bytes
    let declared = if tag.len() == 8 && e.u32(&tag[..4]) >> 16 == 0 {
        u64::from(e.u32(&tag[4..8]))
    } else {
        0
    };
    let total = declared.saturating_add(8 + 7);
    if total > MAX_DECOMPRESSED {
        return Err(bad(format!(
            "has a compressed variable that declares {declared} bytes: {}",
            too_big("it", declared)
        )));
    }
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(tag);
    z.take(total - tag.len() as u64)
        .read_to_end(&mut out)
        .map_err(damaged)?;
    Ok(out)
}

/// Parses one `miMATRIX` element. `None` for an empty element or an unnamed variable (such as
/// MATLAB's hidden function workspace).
fn parse_matrix(data: &[u8], e: Endian) -> Result<Option<Var>, MatError> {
    if data.is_empty() {
        return Ok(None);
    }
    let parts = elements(data, e)?;
    let damaged = || {
        bad(format!(
            "has a damaged variable (array header incomplete); {RESAVE}"
        ))
    };
    let [flags, dims, name, rest @ ..] = parts.as_slice() else {
        return Err(damaged());
    };
    if flags.kind != MI_UINT32 || flags.data.len() < 8 || dims.kind != MI_INT32 {
        return Err(damaged());
    }
    let flag_word = e.u32(&flags.data[..4]);
    let class = (flag_word & 0xff) as u8;
    let complex = flag_word & FLAG_COMPLEX != 0;
    let shape: Vec<usize> = dims
        .data
        .chunks_exact(4)
        .map(|c| e.u32(c) as i32)
        .map(|d| usize::try_from(d).unwrap_or(0))
        .collect();
    let name = String::from_utf8_lossy(name.data)
        .trim_end_matches('\0')
        .to_string();
    if name.is_empty() {
        return Ok(None);
    }
    let unusable = |reason: &str| {
        Ok(Some(Var::Unusable {
            name: name.clone(),
            reason: reason.to_string(),
        }))
    };
    match class {
        MX_CHAR => return unusable("is text (char array)"),
        MX_CELL => return unusable("is a cell array"),
        MX_STRUCT => return unusable("is a struct"),
        MX_OBJECT => return unusable("is an object"),
        MX_SPARSE => return unusable("is a sparse matrix; store it with `full(...)`"),
        c if !(MX_DOUBLE..=MX_UINT64).contains(&c) => {
            return unusable("is not a numeric array (function handle or opaque object)")
        }
        _ => {}
    }
    if complex {
        return unusable(
            "is complex; save the real and imaginary parts as separate real variables",
        );
    }
    let Some(real) = rest.first() else {
        return Err(damaged());
    };
    let values = numbers(real, e).ok_or_else(|| {
        bad(format!(
            "has a damaged variable `{name}` (unknown data type {} or a byte count that does not fit it); {RESAVE}",
            real.kind
        ))
    })?;
    Ok(Some(Var::Numeric {
        name,
        shape,
        order: Order::ColumnMajor,
        data: values,
    }))
}

/// The numbers of a numeric data element, converted to `f64`. MATLAB may store a double array
/// with a smaller integer type, so the element type (not the array class) decides.
fn numbers(el: &Element<'_>, e: Endian) -> Option<Vec<f64>> {
    fn conv<const N: usize>(data: &[u8], f: impl Fn([u8; N]) -> f64) -> Option<Vec<f64>> {
        if data.len() % N != 0 {
            return None;
        }
        Some(
            data.chunks_exact(N)
                .map(|c| {
                    let mut a = [0u8; N];
                    a.copy_from_slice(c);
                    f(a)
                })
                .collect(),
        )
    }
    let d = el.data;
    let b = e.big;
    match el.kind {
        MI_INT8 => conv::<1>(d, |a| f64::from(i8::from_ne_bytes(a))),
        MI_UINT8 => conv::<1>(d, |a| f64::from(a[0])),
        MI_INT16 => conv::<2>(d, |a| {
            f64::from(if b {
                i16::from_be_bytes(a)
            } else {
                i16::from_le_bytes(a)
            })
        }),
        MI_UINT16 => conv::<2>(d, |a| {
            f64::from(if b {
                u16::from_be_bytes(a)
            } else {
                u16::from_le_bytes(a)
            })
        }),
        MI_INT32 => conv::<4>(d, |a| {
            f64::from(if b {
                i32::from_be_bytes(a)
            } else {
                i32::from_le_bytes(a)
            })
        }),
        MI_UINT32 => conv::<4>(d, |a| {
            f64::from(if b {
                u32::from_be_bytes(a)
            } else {
                u32::from_le_bytes(a)
            })
        }),
        MI_SINGLE => conv::<4>(d, |a| {
            f64::from(if b {
                f32::from_be_bytes(a)
            } else {
                f32::from_le_bytes(a)
            })
        }),
        MI_DOUBLE => conv::<8>(d, |a| {
            if b {
                f64::from_be_bytes(a)
            } else {
                f64::from_le_bytes(a)
            }
        }),
        MI_INT64 => conv::<8>(d, |a| {
            (if b {
                i64::from_be_bytes(a)
            } else {
                i64::from_le_bytes(a)
            }) as f64
        }),
        MI_UINT64 => conv::<8>(d, |a| {
            (if b {
                u64::from_be_bytes(a)
            } else {
                u64::from_le_bytes(a)
            }) as f64
        }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little-endian v5 file with the given top-level elements.
    fn file(elements: &[u8]) -> Vec<u8> {
        let mut h = b"MATLAB 5.0 MAT-file, test".to_vec();
        h.resize(124, b' ');
        h.extend_from_slice(&[0x00, 0x01, b'I', b'M']);
        h.extend_from_slice(elements);
        h
    }

    fn element(kind: u32, data: &[u8]) -> Vec<u8> {
        let mut v = kind.to_le_bytes().to_vec();
        v.extend_from_slice(&(data.len() as u32).to_le_bytes());
        v.extend_from_slice(data);
        while v.len() % 8 != 0 {
            v.push(0);
        }
        v
    }

    fn matrix(class: u8, dims: &[i32], name: &str, real: Vec<u8>) -> Vec<u8> {
        let mut m = element(MI_UINT32, &[class, 0, 0, 0, 0, 0, 0, 0]);
        let d: Vec<u8> = dims.iter().flat_map(|x| x.to_le_bytes()).collect();
        m.extend(element(MI_INT32, &d));
        m.extend(element(MI_INT8, name.as_bytes()));
        m.extend(real);
        element(MI_MATRIX, &m)
    }

    /// Big-endian element; `small` uses the small-element form (≤ 4 bytes inside the tag).
    fn be_element(kind: u32, data: &[u8], small: bool) -> Vec<u8> {
        let mut v = if small {
            assert!(data.len() <= 4);
            let mut v = ((data.len() as u32) << 16 | kind).to_be_bytes().to_vec();
            v.extend_from_slice(data);
            v
        } else {
            let mut v = kind.to_be_bytes().to_vec();
            v.extend_from_slice(&(data.len() as u32).to_be_bytes());
            v.extend_from_slice(data);
            v
        };
        while v.len() % 8 != 0 {
            v.push(0);
        }
        v
    }

    #[test]
    fn reads_big_endian_small_elements_and_compressed_variables() {
        use std::io::Write;
        let mut m = be_element(MI_UINT32, &[0, 0, 0, MX_DOUBLE, 0, 0, 0, 0], false);
        m.extend(be_element(MI_INT32, &[0, 0, 0, 4, 0, 0, 0, 1], false));
        m.extend(be_element(MI_INT8, b"yb", true));
        let vals: Vec<u8> = [-3i16, 0, 7, 300]
            .iter()
            .flat_map(|x| x.to_be_bytes())
            .collect();
        m.extend(be_element(MI_INT16, &vals, false));
        let var = be_element(MI_MATRIX, &m, false);
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&var).unwrap();
        let packed = z.finish().unwrap();
        let mut f = b"MATLAB 5.0 MAT-file, big endian".to_vec();
        f.resize(124, b' ');
        f.extend_from_slice(&[0x01, 0x00, b'M', b'I']);
        f.extend_from_slice(&var);
        // compressed elements are not padded
        f.extend_from_slice(&MI_COMPRESSED.to_be_bytes());
        f.extend_from_slice(&(packed.len() as u32).to_be_bytes());
        f.extend_from_slice(&packed);
        let vars = parse(&f).unwrap();
        assert_eq!(vars.len(), 2);
        for v in &vars {
            match v {
                Var::Numeric {
                    name, shape, data, ..
                } => {
                    assert_eq!(name, "yb");
                    assert_eq!(shape, &[4, 1]);
                    assert_eq!(data, &[-3.0, 0.0, 7.0, 300.0]);
                }
                v => panic!("{v:?}"),
            }
        }
    }

    #[test]
    fn reads_double_and_integer_stored_double() {
        let vals: Vec<u8> = [1.5f64, -2.0, 3.25]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let mut body = matrix(MX_DOUBLE, &[3, 1], "x", element(MI_DOUBLE, &vals));
        // a double array stored as uint8 (as MATLAB does for small integers)
        body.extend(matrix(
            MX_DOUBLE,
            &[1, 3],
            "k",
            element(MI_UINT8, &[7, 8, 9]),
        ));
        let vars = parse(&file(&body)).unwrap();
        assert_eq!(vars.len(), 2);
        match &vars[1] {
            Var::Numeric {
                name, data, shape, ..
            } => {
                assert_eq!(name, "k");
                assert_eq!(shape, &[1, 3]);
                assert_eq!(data, &[7.0, 8.0, 9.0]);
            }
            v => panic!("{v:?}"),
        }
    }

    #[test]
    fn damaged_files_give_errors_not_panics() {
        let vals: Vec<u8> = [1.5f64, -2.0, 3.25]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let good = file(&matrix(MX_DOUBLE, &[3, 1], "x", element(MI_DOUBLE, &vals)));
        // every truncation, and every single-byte corruption of the element part
        for n in 0..good.len() {
            let _ = parse(&good[..n]);
        }
        for i in 128..good.len() {
            for v in [0u8, 0xff, 0x7f, 3] {
                let mut b = good.clone();
                b[i] = v;
                let _ = parse(&b);
            }
        }
        assert!(matches!(
            parse(b"MATLAB 7.3 MAT-file, Platform"),
            Err(MatError::V73)
        ));
        assert!(matches!(parse(b"short"), Err(MatError::Bad(_))));
        let mut wrong = good.clone();
        wrong[126] = b'X';
        assert!(matches!(parse(&wrong), Err(MatError::Bad(_))));
        let mut comp = good[..128].to_vec();
        comp.extend(element(MI_COMPRESSED, &[0x78, 0x9c, 1, 2, 3]));
        assert!(matches!(parse(&comp), Err(MatError::Bad(_))));
    }
}
