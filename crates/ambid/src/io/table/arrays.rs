//! Shared by the `.npy`, `.npz` and `.mat` readers: numeric arrays (variables) to named columns.
//!
//! Rules: a vector (1-D, or any shape with one dimension ≠ 1) keeps its name; a 2-D array `v`
//! with shape N×k gives columns `v1`…`vk`, unless k > N, when the signals are taken to be in
//! rows (k samples of N signals); single numbers (such as a stored `Ts`) and empty arrays are not
//! signals and are skipped unless asked for by name; more than two non-singleton dimensions is
//! an error for that variable.

use std::path::Path;

use super::{DataFileError, Table};

/// Largest amount of data one binary data file (`.npy`, `.npz`, `.mat`, `.parquet`) may
/// declare or decompress to: $2^{29}$ bytes (512 MiB, 67 million `f64` values, e.g. 10⁷
/// samples of six signals). It is checked against the sizes the file declares (array shapes,
/// zip member sizes, MAT element lengths, Parquet row counts) *before* anything is inflated or
/// allocated, and inflation itself stops at it, so a small compressed file cannot make the
/// reader allocate gigabytes. Every later step holds the record in memory at a few times its
/// size, which keeps the whole analysis within about 2 GiB.
pub const MAX_DECODED_BYTES: u64 = 1 << 29;

/// The error text for data of `bytes` (as `f64` or decompressed) above [`MAX_DECODED_BYTES`].
pub(super) fn too_big(what: &str, bytes: u64) -> String {
    format!(
        "{what} would take {:.1} MiB in memory, more than the limit of {} MiB for one data file \
         (MAX_DECODED_BYTES); split the record into shorter files or keep only the signals you \
         need",
        bytes as f64 / 1048576.0,
        MAX_DECODED_BYTES >> 20
    )
}

/// Element order of a stored array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Order {
    /// Last index fastest (NumPy default).
    RowMajor,
    /// First index fastest (MATLAB, NumPy `fortran_order`).
    ColumnMajor,
}

/// One variable of a `.npz`/`.mat` file (or the array of a `.npy` file).
#[derive(Debug)]
pub(super) enum Var {
    /// A real numeric array, converted to `f64`.
    Numeric {
        name: String,
        shape: Vec<usize>,
        order: Order,
        data: Vec<f64>,
    },
    /// Something that is not a real numeric array (text, struct, cell, complex, …).
    Unusable { name: String, reason: String },
}

impl Var {
    fn name(&self) -> &str {
        match self {
            Var::Numeric { name, .. } | Var::Unusable { name, .. } => name,
        }
    }
}

/// A named column.
type Column = (String, Vec<f64>);

fn shape_text(shape: &[usize]) -> String {
    if shape.is_empty() {
        return "scalar".into();
    }
    shape
        .iter()
        .map(|d| d.to_string())
        .collect::<Vec<_>>()
        .join("×")
}

/// The columns of one numeric variable, or why it is not a signal (`Err((skippable, reason))`;
/// skippable reasons — a single number, an empty array — are silently skipped unless the
/// variable was asked for by name).
fn columns_of(
    name: &str,
    shape: &[usize],
    order: Order,
    data: &[f64],
) -> Result<Vec<Column>, (bool, String)> {
    let total = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
    if total != Some(data.len()) {
        return Err((
            false,
            format!(
                "has shape {} but {} values (the file is damaged)",
                shape_text(shape),
                data.len()
            ),
        ));
    }
    if data.is_empty() {
        return Err((true, format!("is empty (shape {})", shape_text(shape))));
    }
    let dims: Vec<usize> = shape.iter().copied().filter(|&d| d != 1).collect();
    match dims.as_slice() {
        [] => Err((true, "is a single number, not a signal".into())),
        [_] => Ok(vec![(name.to_string(), data.to_vec())]),
        &[rows, cols] => {
            // Element (i, j) of the rows × cols matrix.
            let at = |i: usize, j: usize| -> f64 {
                let k = match order {
                    Order::RowMajor => i * cols + j,
                    Order::ColumnMajor => i + j * rows,
                };
                data.get(k).copied().unwrap_or(f64::NAN)
            };
            let signals: Vec<Vec<f64>> = if cols > rows {
                (0..rows).map(|i| (0..cols).map(|j| at(i, j)).collect()).collect()
            } else {
                (0..cols).map(|j| (0..rows).map(|i| at(i, j)).collect()).collect()
            };
            Ok(signals
                .into_iter()
                .enumerate()
                .map(|(s, v)| (format!("{name}{}", s + 1), v))
                .collect())
        }
        _ => Err((
            false,
            format!(
                "has shape {}; only vectors and 2-D arrays (samples × signals) can be read: reshape it to 2-D before saving",
                shape_text(shape)
            ),
        )),
    }
}

/// Builds the table from the variables of a file. `selected` picks one variable by name.
pub(super) fn assemble(
    path: &Path,
    vars: Vec<Var>,
    selected: Option<&str>,
) -> Result<Table, DataFileError> {
    let listing = |vars: &[Var]| -> String {
        vars.iter()
            .map(|v| match v {
                Var::Numeric { name, shape, .. } => format!("`{name}` ({})", shape_text(shape)),
                Var::Unusable { name, .. } => format!("`{name}`"),
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut names = Vec::new();
    let mut columns = Vec::new();
    if let Some(want) = selected {
        let Some(var) = vars.iter().find(|v| v.name() == want) else {
            let have = if vars.is_empty() {
                "no variables".to_string()
            } else {
                format!("the variables {}", listing(&vars))
            };
            return Err(DataFileError::invalid(
                path,
                format!(
                    "no variable `{want}`; the file has {have}; set `variable` to one of these"
                ),
            ));
        };
        let cols = match var {
            Var::Unusable { reason, .. } => Err((false, reason.clone())),
            Var::Numeric {
                name,
                shape,
                order,
                data,
            } => columns_of(name, shape, *order, data),
        };
        match cols {
            Ok(cols) => {
                for (n, c) in cols {
                    names.push(n);
                    columns.push(c);
                }
            }
            Err((_, reason)) => {
                return Err(DataFileError::invalid(
                    path,
                    format!("variable `{want}` {reason}; choose another variable"),
                ))
            }
        }
    } else {
        let mut skipped = Vec::new();
        let mut lengths = Vec::new();
        for var in &vars {
            match var {
                Var::Unusable { name, reason } => skipped.push(format!("`{name}` {reason}")),
                Var::Numeric {
                    name,
                    shape,
                    order,
                    data,
                } => match columns_of(name, shape, *order, data) {
                    Ok(cols) => {
                        if let Some((_, first)) = cols.first() {
                            lengths.push(format!("{name}: {}", first.len()));
                        }
                        for (n, c) in cols {
                            names.push(n);
                            columns.push(c);
                        }
                    }
                    Err((true, reason)) => skipped.push(format!("`{name}` {reason}")),
                    Err((false, reason)) => {
                        return Err(DataFileError::invalid(
                            path,
                            format!(
                                "variable `{name}` {reason}; or select another variable with `variable`"
                            ),
                        ))
                    }
                },
            }
        }
        if columns.is_empty() {
            let found = if skipped.is_empty() {
                "the file holds no variables".to_string()
            } else {
                format!("found only: {}", skipped.join("; "))
            };
            return Err(DataFileError::no_data(
                path,
                format!("no numeric signal (a vector or a 2-D array) to read; {found}; save the signals as real numeric arrays"),
            ));
        }
        let n = columns.first().map_or(0, Vec::len);
        if columns.iter().any(|c| c.len() != n) {
            return Err(DataFileError::LengthMismatch {
                path: path.to_path_buf(),
                lengths: lengths.join(", "),
            });
        }
    }
    Ok(Table {
        path: path.to_path_buf(),
        names,
        columns,
        ts_metadata: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn num(name: &str, shape: &[usize], order: Order, data: Vec<f64>) -> Var {
        Var::Numeric {
            name: name.into(),
            shape: shape.to_vec(),
            order,
            data,
        }
    }

    #[test]
    fn naming_and_orientation() {
        let p = Path::new("f.mat");
        // 3 x 2 column-major: columns [1 2 3], [4 5 6]
        let t = assemble(
            p,
            vec![num(
                "v",
                &[3, 2],
                Order::ColumnMajor,
                vec![1., 2., 3., 4., 5., 6.],
            )],
            None,
        )
        .unwrap();
        assert_eq!(t.names, ["v1", "v2"]);
        assert_eq!(t.columns, vec![vec![1., 2., 3.], vec![4., 5., 6.]]);
        // same matrix row-major
        let t = assemble(
            p,
            vec![num(
                "v",
                &[3, 2],
                Order::RowMajor,
                vec![1., 4., 2., 5., 3., 6.],
            )],
            None,
        )
        .unwrap();
        assert_eq!(t.columns, vec![vec![1., 2., 3.], vec![4., 5., 6.]]);
        // 2 x 3 (signals in rows)
        let t = assemble(
            p,
            vec![num(
                "w",
                &[2, 3],
                Order::RowMajor,
                vec![1., 2., 3., 4., 5., 6.],
            )],
            None,
        )
        .unwrap();
        assert_eq!(t.names, ["w1", "w2"]);
        assert_eq!(t.columns, vec![vec![1., 2., 3.], vec![4., 5., 6.]]);
        // row vector keeps its name; scalar is skipped
        let t = assemble(
            p,
            vec![
                num("t", &[1, 3], Order::ColumnMajor, vec![0., 1., 2.]),
                num("Ts", &[1, 1], Order::ColumnMajor, vec![1.]),
            ],
            None,
        )
        .unwrap();
        assert_eq!(t.names, ["t"]);
    }

    #[test]
    fn errors_name_variables() {
        let p = Path::new("f.npz");
        let e = assemble(
            p,
            vec![
                num("a", &[5], Order::RowMajor, vec![0.; 5]),
                num("b", &[4], Order::RowMajor, vec![0.; 4]),
            ],
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("a: 5, b: 4"), "{e}");
        let e = assemble(
            p,
            vec![num("a", &[5], Order::RowMajor, vec![0.; 5])],
            Some("z"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("no variable `z`") && e.contains("`a` (5)"),
            "{e}"
        );
        let e = assemble(
            p,
            vec![num("c", &[2, 2, 2], Order::RowMajor, vec![0.; 8])],
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("2×2×2"), "{e}");
        let e = assemble(p, vec![num("c", &[3], Order::RowMajor, vec![0.; 2])], None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("damaged"), "{e}");
        let e = assemble(
            p,
            vec![Var::Unusable {
                name: "s".into(),
                reason: "is text".into(),
            }],
            None,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("`s` is text"), "{e}");
    }
}
