//! Apache Parquet (cargo feature `parquet`): the flat numeric columns (DOUBLE, FLOAT, INT32,
//! INT64) of all row groups, by name, in schema order. Nulls become NaN. Other columns (text,
//! booleans, nested) are skipped. Compression: none, Snappy and gzip.

use std::path::Path;

use ::parquet::basic::Type as Physical;
use ::parquet::column::reader::ColumnReader;
use ::parquet::file::reader::{FileReader, SerializedFileReader};

use super::arrays::{too_big, MAX_DECODED_BYTES};
use super::{DataFileError, ReadOptions, Table};

/// Rows read per call.
const BATCH: usize = 8192;

pub(super) fn read(path: &Path, opts: &ReadOptions) -> Result<Table, DataFileError> {
    // The parquet crate asserts on some damaged metadata; such a panic becomes an error here
    // (the checks in `read_checked` avoid the known ones, this is the backstop).
    std::panic::catch_unwind(|| read_checked(path, opts)).unwrap_or_else(|_| {
        Err(DataFileError::invalid(
            path,
            "the Parquet reader failed on this file, which looks damaged; write it again or export the data to CSV",
        ))
    })
}

fn read_checked(path: &Path, _opts: &ReadOptions) -> Result<Table, DataFileError> {
    let file = std::fs::File::open(path).map_err(|e| DataFileError::open(path, &e))?;
    let fail = |e: ::parquet::errors::ParquetError| {
        DataFileError::invalid(
            path,
            format!("cannot read the Parquet data ({e}); if it names a compression codec, write the file with snappy, gzip or no compression, or export the data to CSV"),
        )
    };
    let reader = SerializedFileReader::new(file).map_err(fail)?;
    let schema = reader.metadata().file_metadata().schema_descr_ptr();
    // (leaf index, name) of the flat numeric columns.
    let mut wanted = Vec::new();
    let mut skipped = Vec::new();
    for (i, col) in schema.columns().iter().enumerate() {
        let name = col.path().string();
        let numeric = matches!(
            col.physical_type(),
            Physical::DOUBLE | Physical::FLOAT | Physical::INT32 | Physical::INT64
        );
        if numeric && col.max_rep_level() == 0 {
            wanted.push((i, name));
        } else {
            skipped.push(name);
        }
    }
    if wanted.is_empty() {
        return Err(DataFileError::no_data(
            path,
            format!(
                "no numeric columns (found: {}); store the signals as float64 columns",
                if skipped.is_empty() {
                    "none".to_string()
                } else {
                    skipped.join(", ")
                }
            ),
        ));
    }
    // the sizes the metadata declare, before any page is decompressed: the values as f64, and
    // the uncompressed column chunks
    let rows = u64::try_from(reader.metadata().file_metadata().num_rows()).unwrap_or(u64::MAX);
    let as_f64 = rows.saturating_mul(wanted.len() as u64).saturating_mul(8);
    if as_f64 > MAX_DECODED_BYTES {
        return Err(DataFileError::invalid(
            path,
            too_big(
                &format!("{rows} rows of {} numeric columns", wanted.len()),
                as_f64,
            ),
        ));
    }
    let unpacked = reader
        .metadata()
        .row_groups()
        .iter()
        .flat_map(|g| g.columns())
        .map(|c| u64::try_from(c.uncompressed_size()).unwrap_or(u64::MAX))
        .fold(0u64, u64::saturating_add);
    if unpacked > MAX_DECODED_BYTES {
        return Err(DataFileError::invalid(
            path,
            too_big("the uncompressed column chunks", unpacked),
        ));
    }
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); wanted.len()];
    for g in 0..reader.num_row_groups() {
        let group = reader.get_row_group(g).map_err(fail)?;
        // `get_column_reader` asserts that these are not negative.
        let damaged = group.metadata().columns().iter().any(|c| {
            c.data_page_offset() < 0
                || c.dictionary_page_offset().is_some_and(|o| o < 0)
                || c.compressed_size() < 0
        });
        if damaged {
            return Err(DataFileError::invalid(
                path,
                format!("row group {} has negative offsets or sizes: the file is damaged; write it again or export the data to CSV", g + 1),
            ));
        }
        for ((leaf, _), out) in wanted.iter().zip(columns.iter_mut()) {
            let max_def = schema.column(*leaf).max_def_level();
            let col = group.get_column_reader(*leaf).map_err(fail)?;
            match col {
                ColumnReader::DoubleColumnReader(mut r) => read_all(
                    |d, v| r.read_records(BATCH, d, None, v),
                    max_def,
                    out,
                    |x| x,
                ),
                ColumnReader::FloatColumnReader(mut r) => read_all(
                    |d, v| r.read_records(BATCH, d, None, v),
                    max_def,
                    out,
                    f64::from,
                ),
                ColumnReader::Int32ColumnReader(mut r) => read_all(
                    |d, v| r.read_records(BATCH, d, None, v),
                    max_def,
                    out,
                    f64::from,
                ),
                ColumnReader::Int64ColumnReader(mut r) => read_all(
                    |d, v| r.read_records(BATCH, d, None, v),
                    max_def,
                    out,
                    |x| x as f64,
                ),
                _ => Ok(()),
            }
            .map_err(fail)?;
        }
    }
    Ok(Table {
        path: path.to_path_buf(),
        names: wanted.into_iter().map(|(_, n)| n).collect(),
        columns,
        ts_metadata: None,
    })
}

/// Reads a column chunk to the end, appending to `out` (nulls as NaN).
fn read_all<T: Copy>(
    mut next: impl FnMut(
        Option<&mut Vec<i16>>,
        &mut Vec<T>,
    ) -> ::parquet::errors::Result<(usize, usize, usize)>,
    max_def: i16,
    out: &mut Vec<f64>,
    conv: impl Fn(T) -> f64,
) -> ::parquet::errors::Result<()> {
    let mut values = Vec::with_capacity(BATCH);
    let mut defs = Vec::with_capacity(BATCH);
    loop {
        values.clear();
        defs.clear();
        let (records, _, _) = next(
            if max_def > 0 { Some(&mut defs) } else { None },
            &mut values,
        )?;
        if records == 0 {
            return Ok(());
        }
        if max_def > 0 {
            let mut vals = values.iter();
            for &d in &defs {
                out.push(if d == max_def {
                    vals.next().map_or(f64::NAN, |&v| conv(v))
                } else {
                    f64::NAN
                });
            }
        } else {
            out.extend(values.iter().map(|&v| conv(v)));
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use ::parquet::data_type::{DoubleType, FloatType, Int64Type};
    use ::parquet::file::properties::WriterProperties;
    use ::parquet::file::writer::SerializedFileWriter;
    use ::parquet::schema::parser::parse_message_type;

    use super::super::{read_table, ColumnRef};
    use super::*;

    #[test]
    fn reads_what_the_parquet_writer_wrote() {
        let dir = std::env::temp_dir().join(format!("ambid-pq-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("run.parquet");
        let schema = Arc::new(
            parse_message_type(
                "message run { REQUIRED DOUBLE t; REQUIRED FLOAT y; OPTIONAL INT64 k; REQUIRED BINARY label (UTF8); }",
            )
            .unwrap(),
        );
        let props = Arc::new(WriterProperties::builder().build());
        let mut w = SerializedFileWriter::new(std::fs::File::create(&path).unwrap(), schema, props)
            .unwrap();
        for g in 0..2 {
            let mut rg = w.next_row_group().unwrap();
            let mut c = rg.next_column().unwrap().unwrap();
            let t: Vec<f64> = (0..3).map(|i| (g * 3 + i) as f64 * 0.5).collect();
            c.typed::<DoubleType>().write_batch(&t, None, None).unwrap();
            c.close().unwrap();
            let mut c = rg.next_column().unwrap().unwrap();
            c.typed::<FloatType>()
                .write_batch(&[1.5, -2.0, 0.25], None, None)
                .unwrap();
            c.close().unwrap();
            let mut c = rg.next_column().unwrap().unwrap();
            // one null per group
            c.typed::<Int64Type>()
                .write_batch(&[7, 9], Some(&[1, 0, 1]), None)
                .unwrap();
            c.close().unwrap();
            let mut c = rg.next_column().unwrap().unwrap();
            let labels: Vec<::parquet::data_type::ByteArray> =
                ["a", "b", "c"].iter().map(|s| (*s).into()).collect();
            c.typed::<::parquet::data_type::ByteArrayType>()
                .write_batch(&labels, None, None)
                .unwrap();
            c.close().unwrap();
            rg.close().unwrap();
        }
        w.close().unwrap();

        let table = read_table(&path, &ReadOptions::default()).unwrap();
        assert_eq!(table.names, ["t", "y", "k"]);
        assert_eq!(table.len(), 6);
        assert_eq!(
            table.column(&ColumnRef::parse("t")).unwrap(),
            &[0.0, 0.5, 1.0, 1.5, 2.0, 2.5]
        );
        assert_eq!(table.columns[1], [1.5, -2.0, 0.25, 1.5, -2.0, 0.25]);
        let k = &table.columns[2];
        assert_eq!((k[0], k[2], k[3], k[5]), (7.0, 9.0, 7.0, 9.0));
        assert!(k[1].is_nan() && k[4].is_nan());
        assert!(
            (table
                .sample_time(Some(&ColumnRef::parse("t")), None)
                .unwrap()
                - 0.5)
                .abs()
                < 1e-15
        );

        std::fs::write(dir.join("bad.parquet"), b"PAR1 not really").unwrap();
        let e = read_table(&dir.join("bad.parquet"), &ReadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.parquet") && e.contains("Parquet"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
