//! The `.npz` writer: one `<name>.npy` entry per variable in a zip archive (stored, not
//! compressed, with a fixed 1980-01-01 time stamp so the bytes are reproducible); the `.npy`
//! entries are encoded by `npyz`, the archive by `zip` (the crates `io::table` reads with).

use super::{Result, Value, Var};
use npyz::{DType, TypeStr, WriteOptions, WriterBuilder};
use std::io::{self, Cursor, Write};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipWriter};

fn options() -> SimpleFileOptions {
    SimpleFileOptions::default()
        .compression_method(CompressionMethod::Stored)
        .last_modified_time(DateTime::default())
}

fn npy_f64(shape: &[u64], data: &[f64]) -> io::Result<Vec<u8>> {
    let mut buf = Vec::new();
    let mut w = WriteOptions::<f64>::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut buf)
        .begin_nd()?;
    w.extend(data.iter().copied())?;
    w.finish()?;
    Ok(buf)
}

fn npy_text(text: &str) -> io::Result<Vec<u8>> {
    // numpy's str dtype: little-endian UTF-32 code points, at least one (numpy never makes <U0)
    let len = text.chars().count().max(1);
    let ty: TypeStr = format!("<U{len}")
        .parse()
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, format!("{e}")))?;
    let mut buf = Vec::new();
    let mut w = WriteOptions::<str>::new()
        .dtype(DType::Plain(ty))
        .shape(&[])
        .writer(&mut buf)
        .begin_nd()?;
    w.push(text)?;
    w.finish()?;
    Ok(buf)
}

/// Encodes the variables as an `.npz` archive.
pub(super) fn encode(vars: &[Var]) -> Result<Vec<u8>> {
    let mut zip = ZipWriter::new(Cursor::new(Vec::new()));
    for v in vars {
        let bytes = match &v.value {
            Value::Matrix { rows, cols, data } => npy_f64(&[*rows as u64, *cols as u64], data)?,
            Value::Vector(p) => npy_f64(&[p.len() as u64], p)?,
            Value::Scalar(x) => npy_f64(&[], &[*x])?,
            Value::Text(s) => npy_text(s)?,
        };
        zip.start_file(format!("{}.npy", v.name), options())
            .map_err(io::Error::from)?;
        zip.write_all(&bytes)?;
    }
    let cursor = zip.finish().map_err(io::Error::from)?;
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
        let mut zip = zip::ZipArchive::new(Cursor::new(bytes)).unwrap();
        let mut entry = |name: &str| {
            let mut buf = Vec::new();
            std::io::Read::read_to_end(&mut zip.by_name(&format!("{name}.npy")).unwrap(), &mut buf)
                .unwrap();
            npyz::NpyFile::new(Cursor::new(buf)).unwrap()
        };
        let m = entry("M");
        assert_eq!(m.shape(), &[2, 3]);
        assert_eq!(m.into_vec::<f64>().unwrap(), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let p = entry("p");
        assert_eq!(p.shape(), &[2]);
        drop(p);
        let ts = entry("Ts");
        assert_eq!(ts.shape(), &[] as &[u64]);
        assert_eq!(ts.into_vec::<f64>().unwrap(), [1e-3]);
        let s = entry("s");
        assert_eq!(s.dtype().descr(), "'<U3'");
        assert_eq!(s.into_vec::<String>().unwrap(), ["x/ü"]);
        let e = entry("e");
        assert_eq!(e.into_vec::<String>().unwrap(), [""]);
    }
}
