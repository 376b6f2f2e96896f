//! MATLAB `-v7.3` MAT-files: HDF5 files behind a 512-byte user block whose text starts
//! `MATLAB 7.3 MAT-file`, read with the pure-Rust `hdf5-reader` crate (no libhdf5).
//!
//! MATLAB's layout: every variable is an HDF5 object at the root with the attribute
//! `MATLAB_class` (`double`, `single`, `int16`, …, `char`, `logical`, `struct`, `cell`). An
//! $m \times n$ array is stored with its dimensions reversed, as an HDF5 dataset of shape
//! $(n, m)$ (MATLAB is column-major, HDF5 row-major), so a column vector of $N$ samples is
//! $(1, N)$ and MATLAB's $N \times k$ signal matrix is $(k, N)$. A 1×1 struct is a group whose
//! members are its fields; a struct *array* (1×k) is a group whose fields are datasets of $k$
//! object references into the group `#refs#`, one per element.
//!
//! Columns, in the same rules as the v5 reader (`docs/data-files.md`):
//! * a numeric variable `v` gives `v` (a vector) or `v1` … `vk` (an $N \times k$ matrix; with
//!   $k > N$ the signals are in rows);
//! * a struct's fields are `s.field`, nested structs `s.inner.field`;
//! * a struct array (or a 1×1 struct) whose elements each have a name (a char field `label`,
//!   `name` or `Name`) and numeric data (`values`, `Data` or `data`) — Simulink's *structure
//!   with time* (`sim.signals(k).label`/`.values`) and dSPACE ControlDesk's recorder export
//!   (`exp.X(1).Name`/`.Data`, `exp.Y(k).Name`/`.Data`) — gives `s.field.<name>`; other struct
//!   arrays give `s.field(k).inner`.
//!
//! Only the metadata are read when the file is opened; [`Mat73File::read`] reads the rows asked
//! for of one column through an HDF5 hyperslab, so a window of a few signals of a long record
//! never loads the rest.

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use hdf5_reader::error::Error as H5Error;
use hdf5_reader::group::Group;
use hdf5_reader::{Dataset, Datatype, Hdf5File, SliceInfo, SliceInfoElem};

use super::DataFileError;

/// Where one column's samples lie.
#[derive(Clone)]
struct Col {
    name: String,
    ds: Dataset,
    /// The HDF5 axis along which the samples run.
    axis: usize,
    /// The index along the other axis (for a 2-D dataset).
    other: Option<u64>,
    len: u64,
}

/// A variable (or part of one) that is not a signal, with the reason.
#[derive(Debug, Clone)]
pub(super) struct Unusable {
    pub name: String,
    pub reason: String,
}

/// An opened MAT v7.3 file (module docs).
pub(super) struct Mat73File {
    path: PathBuf,
    cols: Vec<Col>,
    pub(super) unusable: Vec<Unusable>,
}

/// Whether the bytes at the start of a `.mat` file announce version 7.3.
pub(super) fn is_v73(start: &[u8]) -> bool {
    start.starts_with(b"MATLAB 7.3")
}

fn h5err(path: &Path, what: &str, e: H5Error) -> DataFileError {
    DataFileError::invalid(
        path,
        format!("{what}: {e}; the MAT-file (HDF5) is damaged or truncated: save it again in MATLAB (`save(f, '-v7.3')`) or copy it again from the rig"),
    )
}

/// The `MATLAB_class` attribute of an object, if it has one.
fn class_of_attr(a: Result<hdf5_reader::Attribute, H5Error>) -> Option<String> {
    a.ok()
        .and_then(|a| a.read_string().ok())
        .map(|s| s.trim_end_matches('\0').to_string())
}

const NUMERIC: [&str; 11] = [
    "double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
    "logical",
];

/// Reads a hyperslab of a dataset as `f64`, whatever its numeric type.
fn read_f64(ds: &Dataset, sel: &SliceInfo) -> Result<Vec<f64>, String> {
    macro_rules! rd {
        ($t:ty) => {{
            let a = ds.read_slice::<$t>(sel).map_err(|e| e.to_string())?;
            a.iter().map(|&v| v as f64).collect()
        }};
    }
    Ok(match ds.dtype() {
        Datatype::FloatingPoint { size: 8, .. } => rd!(f64),
        Datatype::FloatingPoint { size: 4, .. } => rd!(f32),
        Datatype::FixedPoint { size, signed, .. } => match (size, signed) {
            (1, true) => rd!(i8),
            (1, false) => rd!(u8),
            (2, true) => rd!(i16),
            (2, false) => rd!(u16),
            (4, true) => rd!(i32),
            (4, false) => rd!(u32),
            (8, true) => rd!(i64),
            (8, false) => rd!(u64),
            _ => return Err(format!("integers of {size} bytes")),
        },
        other => return Err(format!("HDF5 type {other:?}")),
    })
}

/// A char variable's text (UTF-16 code units).
fn read_char(ds: &Dataset) -> Option<String> {
    let v = ds.read_array::<u16>().ok()?;
    let units: Vec<u16> = v.iter().copied().collect();
    Some(String::from_utf16_lossy(&units))
}

/// The fields that name a signal and hold its samples in a logging struct (Simulink:
/// `label`/`values`; dSPACE: `Name`/`Data`).
const NAME: [&str; 3] = ["label", "name", "Name"];
const DATA: [&str; 3] = ["values", "Data", "data"];

struct Walker<'a> {
    path: &'a Path,
    offset_size: u8,
    /// Objects of `#refs#` by object-header address.
    refs: HashMap<u64, Obj>,
    cols: Vec<Col>,
    unusable: Vec<Unusable>,
}

#[derive(Clone)]
enum Obj {
    Group(Group),
    Dataset(Box<Dataset>),
}

impl Walker<'_> {
    fn unusable(&mut self, name: &str, reason: impl Into<String>) {
        self.unusable.push(Unusable {
            name: name.to_string(),
            reason: reason.into(),
        });
    }

    /// A numeric dataset `ds` named `name`: its columns (module docs).
    fn numeric(&mut self, name: &str, ds: &Dataset) {
        let shape = ds.shape().to_vec();
        let dims: Vec<u64> = shape.iter().copied().filter(|&d| d != 1).collect();
        if shape.contains(&0) {
            self.unusable(name, "an empty array");
            return;
        }
        match (shape.len(), dims.len()) {
            (_, 0) => self.unusable(name, "a single number, not a signal"),
            (_, 1) => {
                // the one dimension that is not 1 (dims.len() == 1)
                let axis = shape.iter().position(|&d| d != 1).unwrap_or(0);
                let other = (shape.len() == 2).then_some(0);
                self.cols.push(Col {
                    name: name.to_string(),
                    ds: ds.clone(),
                    axis,
                    other,
                    len: dims[0],
                });
            }
            (2, 2) => {
                // HDF5 (a, b) is MATLAB b×a: N = b samples of k = a signals, unless k > N
                let (a, b) = (shape[0], shape[1]);
                let (axis, n, k) = if a > b { (0, a, b) } else { (1, b, a) };
                for j in 0..k {
                    self.cols.push(Col {
                        name: format!("{name}{}", j + 1),
                        ds: ds.clone(),
                        axis,
                        other: Some(j),
                        len: n,
                    });
                }
            }
            _ => self.unusable(
                name,
                format!(
                    "an array of {} dimensions (only vectors and matrices are signals)",
                    shape.len()
                ),
            ),
        }
    }

    fn dataset(&mut self, name: &str, ds: &Dataset) {
        let class = class_of_attr(ds.attribute("MATLAB_class"));
        match class.as_deref() {
            Some(c) if NUMERIC.contains(&c) => {
                if matches!(ds.dtype(), Datatype::Compound { .. }) {
                    self.unusable(name, "complex numbers");
                } else {
                    self.numeric(name, ds);
                }
            }
            Some("char") => self.unusable(name, "text"),
            Some("cell") => self.unusable(name, "a cell array"),
            Some(c) => self.unusable(name, format!("of MATLAB class `{c}`")),
            None => match ds.dtype() {
                Datatype::FloatingPoint { .. } | Datatype::FixedPoint { .. } => {
                    self.numeric(name, ds)
                }
                _ => self.unusable(name, "not a numeric array"),
            },
        }
    }

    fn group(&mut self, name: &str, g: &Group, depth: usize) -> Result<(), DataFileError> {
        if depth > 16 {
            self.unusable(name, "structs nested more than 16 deep");
            return Ok(());
        }
        let (groups, datasets) = g
            .members()
            .map_err(|e| h5err(self.path, &format!("struct `{name}`"), e))?;
        // a struct array: its fields are datasets of references
        let is_ref = |d: &Dataset| matches!(d.dtype(), Datatype::Reference { .. });
        if !datasets.is_empty() && datasets.iter().all(is_ref) && groups.is_empty() {
            return self.struct_array(name, &datasets, depth);
        }
        // a 1×1 struct with a name and numeric data (dSPACE's X(1) with one element): as one
        // element of a named struct array
        let by = |keys: &[&str]| datasets.iter().find(|d| keys.contains(&d.name())).cloned();
        if let (Some(n), Some(d)) = (by(&NAME), by(&DATA)) {
            let numeric = class_of_attr(d.attribute("MATLAB_class"))
                .is_some_and(|c| NUMERIC.contains(&c.as_str()));
            if let Some(label) = read_char(&n).filter(|l| !l.is_empty() && numeric) {
                self.dataset(&format!("{name}.{label}"), &d);
                return Ok(());
            }
        }
        for ds in &datasets {
            let field = format!("{name}.{}", ds.name());
            if is_ref(ds) {
                self.unusable(&field, "a cell array");
            } else {
                self.dataset(&field, ds);
            }
        }
        for sub in &groups {
            let field = format!("{name}.{}", sub.name());
            self.group(&field, sub, depth + 1)?;
        }
        Ok(())
    }

    /// The objects the references of dataset `ds` point to.
    fn targets(&self, ds: &Dataset) -> Option<Vec<Obj>> {
        let raw = ds.read_raw_bytes().ok()?;
        let addrs = hdf5_reader::reference::read_object_references(&raw, self.offset_size).ok()?;
        addrs.iter().map(|a| self.refs.get(a).cloned()).collect()
    }

    fn struct_array(
        &mut self,
        name: &str,
        fields: &[Dataset],
        depth: usize,
    ) -> Result<(), DataFileError> {
        let mut elems: Vec<Vec<(String, Obj)>> = Vec::new();
        for f in fields {
            let Some(t) = self.targets(f) else {
                self.unusable(
                    &format!("{name}.{}", f.name()),
                    "references that do not resolve (damaged file?)",
                );
                continue;
            };
            if elems.is_empty() {
                elems = vec![Vec::new(); t.len()];
            }
            for (e, o) in elems.iter_mut().zip(t) {
                e.push((f.name().to_string(), o));
            }
        }
        let find = |e: &[(String, Obj)], keys: &[&str]| -> Option<Obj> {
            keys.iter()
                .find_map(|k| e.iter().find(|(n, _)| n == k).map(|(_, o)| o.clone()))
        };
        let named: Option<Vec<(String, Dataset)>> = elems
            .iter()
            .map(|e| match (find(e, &NAME), find(e, &DATA)) {
                (Some(Obj::Dataset(n)), Some(Obj::Dataset(d))) => {
                    let label = read_char(&n)?;
                    (!label.is_empty()).then_some((label, *d))
                }
                _ => None,
            })
            .collect();
        match named {
            Some(named) if !named.is_empty() => {
                for (label, d) in named {
                    self.dataset(&format!("{name}.{label}"), &d);
                }
            }
            _ => {
                for (k, e) in elems.iter().enumerate() {
                    for (field, o) in e {
                        let n = format!("{name}({}).{field}", k + 1);
                        match o {
                            Obj::Dataset(d) => self.dataset(&n, d),
                            Obj::Group(g) => self.group(&n, g, depth + 1)?,
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

impl Mat73File {
    /// Opens the file and lists its columns (module docs); `variable` keeps only the columns
    /// of that variable.
    pub(super) fn open(path: &Path, variable: Option<&str>) -> Result<Mat73File, DataFileError> {
        let file = Hdf5File::open(path).map_err(|e| match e {
            H5Error::Io(io) => DataFileError::open(path, &io),
            H5Error::InvalidMagic => DataFileError::invalid(
                path,
                "the header says MATLAB 7.3 MAT-file, but no HDF5 data follow it (no HDF5 signature at byte 512 or later); the file is damaged: save it again in MATLAB",
            ),
            e => h5err(path, "cannot open the HDF5 part", e),
        })?;
        let root = file
            .root_group()
            .map_err(|e| h5err(path, "the root group", e))?;
        let mut w = Walker {
            path,
            offset_size: root.offset_size(),
            refs: HashMap::new(),
            cols: Vec::new(),
            unusable: Vec::new(),
        };
        let (groups, datasets) = root
            .members()
            .map_err(|e| h5err(path, "the list of variables", e))?;
        if let Some(r) = groups.iter().find(|g| g.name() == "#refs#") {
            let (rg, rd) = r
                .members()
                .map_err(|e| h5err(path, "the group #refs#", e))?;
            for g in rg {
                w.refs.insert(g.address(), Obj::Group(g));
            }
            for d in rd {
                w.refs.insert(d.address(), Obj::Dataset(Box::new(d)));
            }
        }
        let keep = |n: &str| variable.is_none_or(|v| v == n);
        for ds in &datasets {
            if keep(ds.name()) {
                w.dataset(ds.name(), ds);
            }
        }
        for g in &groups {
            if g.name() != "#refs#" && g.name() != "#subsystem#" && keep(g.name()) {
                let class = class_of_attr(g.attribute("MATLAB_class"));
                if class.as_deref().is_some_and(|c| c != "struct") {
                    w.unusable(
                        g.name(),
                        format!("of MATLAB class `{}`", class.unwrap_or_default()),
                    );
                    continue;
                }
                w.group(g.name(), g, 0)?;
            }
        }
        Ok(Mat73File {
            path: path.to_path_buf(),
            cols: w.cols,
            unusable: w.unusable,
        })
    }

    /// The column names, in file order (variables, then structs).
    pub(super) fn names(&self) -> Vec<String> {
        self.cols.iter().map(|c| c.name.clone()).collect()
    }

    /// Number of samples of column `k`.
    pub(super) fn len(&self, k: usize) -> u64 {
        self.cols[k].len
    }

    /// The rows `rows` of column `k` as `f64`.
    pub(super) fn read(&self, k: usize, rows: Range<u64>) -> Result<Vec<f64>, DataFileError> {
        let c = &self.cols[k];
        let (lo, hi) = (rows.start.min(c.len), rows.end.min(c.len));
        if hi <= lo {
            return Ok(Vec::new());
        }
        let ndim = c.ds.shape().len();
        let sel = SliceInfo {
            selections: (0..ndim)
                .map(|a| {
                    if a == c.axis {
                        SliceInfoElem::Slice {
                            start: lo,
                            end: hi,
                            step: 1,
                        }
                    } else {
                        SliceInfoElem::Index(c.other.unwrap_or(0))
                    }
                })
                .collect(),
        };
        read_f64(&c.ds, &sel).map_err(|e| {
            DataFileError::invalid(
                &self.path,
                format!(
                    "variable `{}` (HDF5 dataset `{}`): cannot read its values ({e}); the file is damaged or truncated: save it again in MATLAB",
                    c.name,
                    c.ds.name()
                ),
            )
        })
    }
}
