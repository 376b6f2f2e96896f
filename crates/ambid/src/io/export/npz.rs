//! The `.npz` writer: one `<name>.npy` entry per variable in a zip archive (stored, not
//! compressed, with a fixed 1980-01-01 time stamp so the bytes are reproducible), written with
//! `npyz`.

use super::{Result, Value, Var};
use npyz::zip::{write::FileOptions, CompressionMethod, DateTime};
use npyz::{DType, TypeStr, WriterBuilder};
use std::io::{self, Cursor};

fn options() -> FileOptions {
    FileOptions::default()
        .compression_method(CompressionMethod::Stored)
        .last_modified_time(DateTime::default())
}

fn write_f64<W: io::Write + io::Seek>(
    npz: &mut npyz::npz::NpzWriter<W>,
    name: &str,
    shape: &[u64],
    data: &[f64],
) -> io::Result<()> {
    let mut w = npz
        .array::<f64>(name, options())?
        .default_dtype()
        .shape(shape)
        .begin_nd()?;
    w.extend(data.iter().copied())?;
    w.finish()
}

fn write_text<W: io::Write + io::Seek>(
    npz: &mut npyz::npz::NpzWriter<W>,
    name: &str,
    text: &str,
) -> io::Result<()> {
    // numpy's str dtype: little-endian UTF-32 code points, at least one (numpy never makes <U0)
    let len = text.chars().count().max(1);
    let ty: TypeStr = format!("<U{len}")
        .parse()
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, format!("{e}")))?;
    let mut w = npz
        .array::<str>(name, options())?
        .dtype(DType::Plain(ty))
        .shape(&[])
        .begin_nd()?;
    w.push(text)?;
    w.finish()
}

/// Encodes the variables as an `.npz` archive.
pub(super) fn encode(vars: &[Var]) -> Result<Vec<u8>> {
    let mut npz = npyz::npz::NpzWriter::new(Cursor::new(Vec::new()));
    for v in vars {
        match &v.value {
            Value::Matrix { rows, cols, data } => {
                write_f64(&mut npz, v.name, &[*rows as u64, *cols as u64], data)?
            }
            Value::Vector(p) => write_f64(&mut npz, v.name, &[p.len() as u64], p)?,
            Value::Scalar(x) => write_f64(&mut npz, v.name, &[], &[*x])?,
            Value::Text(s) => write_text(&mut npz, v.name, s)?,
        }
    }
    let cursor = npz.zip_writer().finish().map_err(io::Error::from)?;
    Ok(cursor.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_through_npyz() {
        let vars = [
            Var {
                name: "M",
                value: Value::Matrix {
                    rows: 2,
                    cols: 3,
                    data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
                },
            },
            Var {
                name: "p",
                value: Value::Vector(vec![1.0, -0.5]),
            },
            Var {
                name: "Ts",
                value: Value::Scalar(1e-3),
            },
            Var {
                name: "s",
                value: Value::Text("x/ü".into()),
            },
            Var {
                name: "e",
                value: Value::Text(String::new()),
            },
        ];
        let bytes = encode(&vars).unwrap();
        assert_eq!(bytes, encode(&vars).unwrap(), "reproducible bytes");
        let mut a = npyz::npz::NpzArchive::new(Cursor::new(bytes)).unwrap();
        let m = a.by_name("M").unwrap().unwrap();
        assert_eq!(m.shape(), &[2, 3]);
        assert_eq!(m.into_vec::<f64>().unwrap(), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let p = a.by_name("p").unwrap().unwrap();
        assert_eq!(p.shape(), &[2]);
        drop(p);
        let ts = a.by_name("Ts").unwrap().unwrap();
        assert_eq!(ts.shape(), &[] as &[u64]);
        assert_eq!(ts.into_vec::<f64>().unwrap(), [1e-3]);
        let s = a.by_name("s").unwrap().unwrap();
        assert_eq!(s.dtype().descr(), "'<U3'");
        assert_eq!(s.into_vec::<String>().unwrap(), ["x/ü"]);
        let e = a.by_name("e").unwrap().unwrap();
        assert_eq!(e.into_vec::<String>().unwrap(), [""]);
    }
}
