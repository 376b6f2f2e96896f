//! NI LabVIEW TDMS files (format version 4712/4713): own reader that indexes the file by its
//! segment lead-ins and metadata and then reads only the samples asked for.
//!
//! A TDMS file is a sequence of segments. Each starts with a 28-byte lead-in: the tag `TDSm`,
//! a table-of-contents mask (metadata present, new object list, raw data present, interleaved,
//! big-endian, DAQmx raw data), the version, the offset of the next segment and the offset of
//! the raw data, both counted from the end of the lead-in. The metadata lists objects (`/`,
//! `/'group'`, `/'group'/'channel'`) with a raw-data index (data type, dimension 1, number of
//! values per chunk; `0x00000000` = as in the previous segment, `0xFFFFFFFF` = no data here) and
//! properties. Without the "new object list" flag a segment keeps the previous segment's channel
//! list and adds or updates the objects it names; without metadata it repeats the previous
//! segment's layout. The raw data are whole chunks, each chunk holding every listed channel's
//! values one channel after the other (or, interleaved, sample by sample).
//!
//! [`TdmsFile::open`] reads only the lead-ins and the metadata (one seek per segment) and keeps,
//! per channel and segment, where its values lie: memory in the number of segments, not
//! samples. [`TdmsFile::read`] then reads the bytes of the wanted sample range of one channel.
//!
//! Columns are named `group/channel`. The sample time comes from the channel property
//! `wf_increment`. Raw values are scaled when the channel says so (`NI_Scaling_Status` =
//! `unscaled` with `NI_Number_Of_Scales` ≥ 1: linear and polynomial scales, chained through
//! `NI_Scale[k]_…_Input_Source`). Strings, timestamps, complex values and DAQmx raw data are not
//! signals: such a channel is listed but reading it is an error that says why.
//!
//! Every length and offset read from the file is checked against the file's size before it is
//! used; a damaged file gives an error naming the file and the segment or object, never a panic.

use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::{Path, PathBuf};

use super::DataFileError;

const TOC_META: u32 = 1 << 1;
const TOC_NEW_OBJ_LIST: u32 = 1 << 2;
const TOC_RAW: u32 = 1 << 3;
const TOC_INTERLEAVED: u32 = 1 << 5;
const TOC_BIG_ENDIAN: u32 = 1 << 6;
const TOC_DAQMX: u32 = 1 << 7;
const LEAD_IN: u64 = 28;
/// Largest metadata block accepted (the object paths and properties of one segment).
const MAX_META_BYTES: u64 = 64 << 20;
/// Largest string (object path, property value) accepted.
const MAX_STRING_BYTES: u32 = 1 << 20;

/// A TDMS data type (`tdsType…`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DataType {
    I8,
    I16,
    I32,
    I64,
    U8,
    U16,
    U32,
    U64,
    F32,
    F64,
    Bool,
    /// Not a signal: strings, timestamps, complex, extended float, fixed point, DAQmx.
    Other(u32),
}

impl DataType {
    fn from_code(c: u32) -> DataType {
        match c {
            1 => DataType::I8,
            2 => DataType::I16,
            3 => DataType::I32,
            4 => DataType::I64,
            5 => DataType::U8,
            6 => DataType::U16,
            7 => DataType::U32,
            8 => DataType::U64,
            9 | 0x19 => DataType::F32,
            10 | 0x1A => DataType::F64,
            0x21 => DataType::Bool,
            other => DataType::Other(other),
        }
    }

    /// Bytes per value of a fixed-size type.
    fn size(self) -> Option<u64> {
        Some(match self {
            DataType::I8 | DataType::U8 | DataType::Bool => 1,
            DataType::I16 | DataType::U16 => 2,
            DataType::I32 | DataType::U32 | DataType::F32 => 4,
            DataType::I64 | DataType::U64 | DataType::F64 => 8,
            DataType::Other(c) => match c {
                0x44 => 16,        // timestamp
                0x08000c => 8,     // complex single
                0x10000d => 16,    // complex double
                0x0B | 0x1B => 16, // extended float (stored in 16 bytes)
                _ => return None,  // string (0x20), fixed point, DAQmx, unknown
            },
        })
    }

    fn describe(self) -> String {
        match self {
            DataType::Other(0x20) => "strings".into(),
            DataType::Other(0x44) => "timestamps".into(),
            DataType::Other(0x08000c) | DataType::Other(0x10000d) => "complex values".into(),
            DataType::Other(0x0B) | DataType::Other(0x1B) => "extended-precision floats".into(),
            DataType::Other(0x4F) => "fixed-point values".into(),
            DataType::Other(0xFFFF_FFFF) => "DAQmx raw data".into(),
            DataType::Other(c) => format!("values of TDMS type 0x{c:X}"),
            _ => "numbers".into(),
        }
    }

    fn numeric(self) -> bool {
        !matches!(self, DataType::Other(_))
    }
}

/// A property value.
#[derive(Debug, Clone, PartialEq)]
enum Prop {
    Num(f64),
    Str(String),
    Other,
}

/// The raw-data index of an object in one segment.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Index {
    dtype: DataType,
    /// Values per chunk.
    count: u64,
    /// Bytes per chunk (strings: the declared total size).
    bytes: u64,
}

/// Where one channel's values lie in one segment: `chunks` chunks, the first value of chunk
/// `c` at `first + c·chunk_step`, `count` values per chunk `stride` bytes apart.
#[derive(Debug, Clone)]
struct Run {
    /// Sample index of the run's first value in the channel.
    start: u64,
    first: u64,
    chunk_step: u64,
    chunks: u64,
    count: u64,
    stride: u64,
    dtype: DataType,
    big_endian: bool,
}

impl Run {
    fn len(&self) -> u64 {
        self.chunks * self.count
    }
}

/// One channel (`/'group'/'channel'`).
#[derive(Debug, Clone, Default)]
struct Channel {
    name: String,
    group: String,
    props: HashMap<String, Prop>,
    runs: Vec<Run>,
    /// Values in `runs`.
    total: u64,
    dtype: Option<DataType>,
    /// The index of the last segment that had data for it (for `0x00000000`).
    last_index: Option<Index>,
}

impl Channel {
    fn len(&self) -> u64 {
        self.total
    }

    /// Appends a run after the channel's last value (`run.start` is set here).
    fn push(&mut self, mut run: Run) {
        run.start = self.total;
        self.total += run.len();
        self.runs.push(run);
    }
}

/// An indexed TDMS file (module docs).
#[derive(Debug)]
pub(super) struct TdmsFile {
    path: PathBuf,
    file: File,
    channels: Vec<Channel>,
}

/// Little/big-endian cursor over a metadata block, every read bounds-checked.
struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
    big: bool,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or_else(|| "the metadata end before the objects they declare".to_string())?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    /// The next `N` bytes as an array.
    fn arr<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }

    fn u32(&mut self) -> Result<u32, String> {
        let b: [u8; 4] = self.arr()?;
        Ok(if self.big {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        })
    }

    fn u64(&mut self) -> Result<u64, String> {
        let b: [u8; 8] = self.arr()?;
        Ok(if self.big {
            u64::from_be_bytes(b)
        } else {
            u64::from_le_bytes(b)
        })
    }

    fn string(&mut self) -> Result<String, String> {
        let n = self.u32()?;
        if n > MAX_STRING_BYTES {
            return Err(format!(
                "a string of {n} bytes in the metadata (damaged file?)"
            ));
        }
        let b = self.take(n as usize)?;
        String::from_utf8(b.to_vec()).map_err(|_| "a string in the metadata is not UTF-8".into())
    }

    /// A property value of type `t`.
    fn prop(&mut self, t: u32) -> Result<Prop, String> {
        let big = self.big;
        let int = |b: &[u8], signed: bool| -> f64 {
            let mut v: u64 = 0;
            if big {
                for &x in b {
                    v = (v << 8) | x as u64;
                }
            } else {
                for &x in b.iter().rev() {
                    v = (v << 8) | x as u64;
                }
            }
            let bits = 8 * b.len() as u32;
            if signed && bits < 64 && v >> (bits - 1) == 1 {
                (v as i64 - (1i64 << bits)) as f64
            } else if signed {
                v as i64 as f64
            } else {
                v as f64
            }
        };
        Ok(match DataType::from_code(t) {
            DataType::I8 => Prop::Num(int(self.take(1)?, true)),
            DataType::I16 => Prop::Num(int(self.take(2)?, true)),
            DataType::I32 => Prop::Num(int(self.take(4)?, true)),
            DataType::I64 => Prop::Num(int(self.take(8)?, true)),
            DataType::U8 | DataType::Bool => Prop::Num(int(self.take(1)?, false)),
            DataType::U16 => Prop::Num(int(self.take(2)?, false)),
            DataType::U32 => Prop::Num(int(self.take(4)?, false)),
            DataType::U64 => Prop::Num(int(self.take(8)?, false)),
            DataType::F32 => {
                let b: [u8; 4] = self.arr()?;
                Prop::Num(if big {
                    f32::from_be_bytes(b)
                } else {
                    f32::from_le_bytes(b)
                } as f64)
            }
            DataType::F64 => {
                let b: [u8; 8] = self.arr()?;
                Prop::Num(if big {
                    f64::from_be_bytes(b)
                } else {
                    f64::from_le_bytes(b)
                })
            }
            DataType::Other(0x20) => Prop::Str(self.string()?),
            other => match other.size() {
                Some(n) => {
                    self.take(n as usize)?;
                    Prop::Other
                }
                None => {
                    return Err(format!(
                        "a property of TDMS type 0x{t:X}, whose size ambid does not know"
                    ))
                }
            },
        })
    }
}

/// The object path `/'group'/'channel'` split into its names (`''` inside a name is `'`).
fn split_path(p: &str) -> Option<Vec<String>> {
    if p == "/" {
        return Some(Vec::new());
    }
    let mut out = Vec::new();
    let b = p.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'/' || i + 1 >= b.len() || b[i + 1] != b'\'' {
            return None;
        }
        i += 2;
        let mut name = Vec::new();
        loop {
            if i >= b.len() {
                return None;
            }
            if b[i] == b'\'' {
                if i + 1 < b.len() && b[i + 1] == b'\'' {
                    name.push(b'\'');
                    i += 2;
                    continue;
                }
                i += 1;
                break;
            }
            name.push(b[i]);
            i += 1;
        }
        out.push(String::from_utf8(name).ok()?);
    }
    Some(out)
}

impl TdmsFile {
    fn err(&self, message: impl Into<String>) -> DataFileError {
        DataFileError::invalid(&self.path, message)
    }

    /// Indexes the file: every segment's lead-in and metadata (module docs).
    pub(super) fn open(path: &Path) -> Result<TdmsFile, DataFileError> {
        let mut file = File::open(path).map_err(|e| DataFileError::open(path, &e))?;
        let size = file
            .metadata()
            .map_err(|e| DataFileError::open(path, &e))?
            .len();
        let mut me = TdmsFile {
            path: path.to_path_buf(),
            file: file
                .try_clone()
                .map_err(|e| DataFileError::open(path, &e))?,
            channels: Vec::new(),
        };
        let mut by_path: HashMap<String, usize> = HashMap::new();
        // the channels with data in the current segment's list, in order
        let mut list: Vec<usize> = Vec::new();
        let mut pos = 0u64;
        let mut segment = 0usize;
        while pos < size {
            segment += 1;
            let mut lead = [0u8; LEAD_IN as usize];
            if size - pos < LEAD_IN {
                return Err(me.err(format!(
                    "segment {segment} at byte {pos}: the file ends {} bytes into its 28-byte lead-in; the file is truncated (copy it again from the rig, or cut it before this segment)",
                    size - pos
                )));
            }
            file.seek(SeekFrom::Start(pos))
                .and_then(|_| file.read_exact(&mut lead))
                .map_err(|e| DataFileError::open(path, &e))?;
            if &lead[..4] != b"TDSm" {
                return Err(me.err(if segment == 1 {
                    format!(
                        "not a TDMS file: it starts with {:?} where a TDMS file has the lead-in tag \"TDSm\" (is this the .tdms_index file, or another format? give --format)",
                        String::from_utf8_lossy(&lead[..4])
                    )
                } else {
                    format!(
                        "segment {segment} at byte {pos} has the lead-in tag {:?} instead of \"TDSm\"; the file is damaged after byte {pos}",
                        String::from_utf8_lossy(&lead[..4])
                    )
                }));
            }
            let toc = u32::from_le_bytes([lead[4], lead[5], lead[6], lead[7]]);
            let big = toc & TOC_BIG_ENDIAN != 0;
            let mut c = Cursor {
                buf: &lead[8..],
                pos: 0,
                big,
            };
            let version = c.u32().map_err(|m| me.err(m))?;
            if version != 4712 && version != 4713 {
                return Err(me.err(format!(
                    "segment {segment} at byte {pos}: TDMS version {version}; ambid reads versions 4712 and 4713 (TDMS 1.0 and 2.0)"
                )));
            }
            let next_rel = c.u64().map_err(|m| me.err(m))?;
            let raw_rel = c.u64().map_err(|m| me.err(m))?;
            let body = pos + LEAD_IN;
            // 0xFFFF…: the writer stopped before finishing the segment; its data run to the end
            let incomplete = next_rel == u64::MAX;
            let next = if incomplete {
                size
            } else {
                body.checked_add(next_rel).ok_or_else(|| {
                    me.err(format!("segment {segment} at byte {pos}: a next-segment offset of {next_rel} bytes (damaged lead-in)"))
                })?
            };
            if next > size {
                return Err(me.err(format!(
                    "segment {segment} at byte {pos} declares {} bytes but the file ends after {}; the file is truncated (copy it again from the rig; a recording that was interrupted is marked as such by LabVIEW and would be read)",
                    next - body,
                    size - body
                )));
            }
            let raw_start = body.checked_add(raw_rel).filter(|&r| r <= next).ok_or_else(|| {
                me.err(format!(
                    "segment {segment} at byte {pos}: its raw data would start at offset {raw_rel}, beyond the segment's end (damaged lead-in)"
                ))
            })?;
            if toc & TOC_DAQMX != 0 && toc & TOC_RAW != 0 {
                return Err(me.err(format!(
                    "segment {segment} at byte {pos} holds DAQmx raw data, which ambid does not decode; save the channels as scaled data (e.g. LabVIEW's TDMS Write of the scaled waveform, or DIAdem/npTDMS export to a plain TDMS or CSV file)"
                )));
            }
            if toc & TOC_META != 0 {
                let meta_len = raw_start - body;
                if meta_len > MAX_META_BYTES {
                    return Err(me.err(format!(
                        "segment {segment} at byte {pos}: {meta_len} bytes of metadata (damaged lead-in?)"
                    )));
                }
                let mut meta = vec![0u8; meta_len as usize];
                file.seek(SeekFrom::Start(body))
                    .and_then(|_| file.read_exact(&mut meta))
                    .map_err(|e| DataFileError::open(path, &e))?;
                me.metadata(&meta, big, toc, &mut by_path, &mut list)
                    .map_err(|m| me.err(format!("segment {segment} at byte {pos}: {m}")))?;
            } else if segment == 1 && toc & TOC_RAW != 0 {
                return Err(me.err(
                    "the first segment has raw data but no metadata, so nothing says whose data they are (damaged file)",
                ));
            }
            if toc & TOC_RAW != 0 && !list.is_empty() {
                let interleaved = toc & TOC_INTERLEAVED != 0;
                me.layout(
                    &list,
                    raw_start,
                    next - raw_start,
                    interleaved,
                    big,
                    incomplete,
                )
                .map_err(|m| me.err(format!("segment {segment} at byte {pos}: {m}")))?;
            }
            if next <= pos {
                return Err(me.err(format!(
                    "segment {segment} at byte {pos}: a next-segment offset that does not move forward (damaged lead-in)"
                )));
            }
            pos = next;
        }
        if segment == 0 {
            return Err(DataFileError::no_data(path, "the file is empty"));
        }
        Ok(me)
    }

    /// Reads one segment's metadata: objects, raw-data indices and properties.
    fn metadata(
        &mut self,
        meta: &[u8],
        big: bool,
        toc: u32,
        by_path: &mut HashMap<String, usize>,
        list: &mut Vec<usize>,
    ) -> Result<(), String> {
        let mut c = Cursor {
            buf: meta,
            pos: 0,
            big,
        };
        let n = c.u32()?;
        if toc & TOC_NEW_OBJ_LIST != 0 {
            list.clear();
        }
        for _ in 0..n {
            let opath = c.string()?;
            let names = split_path(&opath).ok_or_else(|| {
                format!("the object path {opath:?} is not of the form /'group'/'channel'")
            })?;
            let raw = c.u32()?;
            let index = match raw {
                0xFFFF_FFFF => None,
                0 => Some(None),
                0x6912_0000 | 0x6913_0000 => {
                    return Err(format!(
                        "the object {opath} holds DAQmx raw data, which ambid does not decode; save the channels as scaled data"
                    ))
                }
                len => {
                    let start = c.pos;
                    let code = c.u32()?;
                    let dim = c.u32()?;
                    let count = c.u64()?;
                    if dim != 1 {
                        return Err(format!(
                            "the object {opath} has raw data of dimension {dim}; TDMS allows only 1 (damaged file)"
                        ));
                    }
                    let dtype = DataType::from_code(code);
                    let bytes = match dtype.size() {
                        Some(s) => count.checked_mul(s).ok_or("a value count too large")?,
                        None if code == 0x20 => c.u64()?,
                        None => {
                            return Err(format!(
                                "the object {opath} has data of TDMS type 0x{code:X}, whose size ambid does not know"
                            ))
                        }
                    };
                    // the index may be longer than what we read (future versions): skip to its end
                    // (the length counts its own 4 bytes)
                    let end = (start + len as usize)
                        .checked_sub(4)
                        .filter(|&e| e <= meta.len() && e >= c.pos)
                        .ok_or_else(|| format!("the raw-data index of {opath} has a bad length {len}"))?;
                    c.pos = end;
                    Some(Some(Index {
                        dtype,
                        count,
                        bytes,
                    }))
                }
            };
            let nprops = c.u32()?;
            let mut props = Vec::new();
            for _ in 0..nprops {
                let name = c.string()?;
                let t = c.u32()?;
                props.push((name, c.prop(t)?));
            }
            if names.len() != 2 {
                // the file (/) and groups (/'g') have no data; their properties are not needed
                if index.is_some_and(|i| i.is_some_and(|i| i.count > 0)) {
                    return Err(format!(
                        "the object {opath} is not a channel but has raw data"
                    ));
                }
                continue;
            }
            let k = match by_path.get(&opath) {
                Some(&k) => k,
                None => {
                    self.channels.push(Channel {
                        name: format!("{}/{}", names[0], names[1]),
                        group: names[0].clone(),
                        ..Channel::default()
                    });
                    by_path.insert(opath.clone(), self.channels.len() - 1);
                    self.channels.len() - 1
                }
            };
            let ch = &mut self.channels[k];
            for (name, p) in props {
                ch.props.insert(name, p);
            }
            match index {
                None => list.retain(|&j| j != k),
                Some(ix) => {
                    let ix = match ix {
                        Some(ix) => ix,
                        None => ch.last_index.ok_or_else(|| {
                            format!("the object {opath} reuses a previous raw-data index it never had (damaged file)")
                        })?,
                    };
                    if let Some(d) = ch.dtype {
                        if d != ix.dtype {
                            return Err(format!(
                                "the channel {} changes its data type between segments, which TDMS does not allow (damaged file)",
                                ch.name
                            ));
                        }
                    }
                    ch.dtype = Some(ix.dtype);
                    ch.last_index = Some(ix);
                    if !list.contains(&k) {
                        list.push(k);
                    }
                }
            }
        }
        Ok(())
    }

    /// Records where each listed channel's values lie in a segment's raw data.
    fn layout(
        &mut self,
        list: &[usize],
        raw_start: u64,
        raw_len: u64,
        interleaved: bool,
        big: bool,
        incomplete: bool,
    ) -> Result<(), String> {
        let idx: Vec<Index> = list
            .iter()
            .map(|&k| {
                self.channels[k].last_index.ok_or_else(|| {
                    format!(
                        "the channel {} has data but no raw-data index (damaged file)",
                        self.channels[k].name
                    )
                })
            })
            .collect::<Result<_, _>>()?;
        let chunk: u64 = idx.iter().map(|i| i.bytes).sum();
        if chunk == 0 {
            return Ok(());
        }
        if interleaved {
            if let Some(i) = idx.iter().find(|i| i.dtype.size().is_none()) {
                return Err(format!(
                    "interleaved raw data with {} (variable size), which TDMS does not allow (damaged file)",
                    i.dtype.describe()
                ));
            }
            if idx.iter().any(|i| i.count != idx[0].count) {
                return Err(
                    "interleaved channels with different value counts (damaged file)".into(),
                );
            }
        }
        let chunks = raw_len / chunk;
        let rest = raw_len % chunk;
        if rest != 0 && !incomplete {
            return Err(format!(
                "{raw_len} bytes of raw data are not a whole number of {chunk}-byte chunks (damaged file)"
            ));
        }
        // bytes per row of interleaved data (every value of one sample index)
        let row: u64 = idx.iter().map(|i| i.dtype.size().unwrap_or(0)).sum();
        let mut off = 0u64;
        for (&k, i) in list.iter().zip(&idx) {
            let ch = &mut self.channels[k];
            let size = i.dtype.size().unwrap_or(0);
            if chunks > 0 {
                ch.push(Run {
                    start: 0,
                    first: raw_start + off,
                    chunk_step: chunk,
                    chunks,
                    count: i.count,
                    stride: if interleaved { row } else { size },
                    dtype: i.dtype,
                    big_endian: big,
                });
            }
            // the last segment of an interrupted recording: the values wholly inside the file
            // (interleaved: the whole rows; contiguous: each channel's part of the last chunk)
            let have = match (incomplete && rest > 0, interleaved) {
                (false, _) => 0,
                (true, true) => rest / row.max(1),
                (true, false) if rest > off && size > 0 => ((rest - off) / size).min(i.count),
                (true, false) => 0,
            };
            if have > 0 {
                ch.push(Run {
                    start: 0,
                    first: raw_start + chunks * chunk + off,
                    chunk_step: chunk,
                    chunks: 1,
                    count: have,
                    stride: if interleaved { row } else { size },
                    dtype: i.dtype,
                    big_endian: big,
                });
            }
            off += if interleaved { size } else { i.bytes };
        }
        Ok(())
    }

    /// Every channel's name (`group/channel`), in file order.
    pub(super) fn names(&self) -> Vec<String> {
        self.channels.iter().map(|c| c.name.clone()).collect()
    }

    /// The group of channel `k`.
    pub(super) fn group(&self, k: usize) -> &str {
        &self.channels[k].group
    }

    /// Whether channel `k` holds numbers (else reading it is an error).
    pub(super) fn is_numeric(&self, k: usize) -> bool {
        self.channels[k].dtype.is_none_or(DataType::numeric)
    }

    /// Number of values of channel `k`.
    pub(super) fn len(&self, k: usize) -> u64 {
        self.channels[k].len()
    }

    /// The sample time of channel `k` from its `wf_increment` property, when it has one.
    pub(super) fn sample_time(&self, k: usize) -> Option<f64> {
        match self.channels[k].props.get("wf_increment") {
            Some(Prop::Num(v)) if v.is_finite() && *v > 0.0 => Some(*v),
            _ => None,
        }
    }

    /// The scaling of channel `k`: `None` for values stored scaled.
    fn scaling(&self, k: usize) -> Result<Option<Scaling>, DataFileError> {
        let ch = &self.channels[k];
        let status = match ch.props.get("NI_Scaling_Status") {
            Some(Prop::Str(s)) => s.as_str(),
            _ => return Ok(None),
        };
        if status != "unscaled" {
            return Ok(None);
        }
        let n = match ch.props.get("NI_Number_Of_Scales") {
            Some(Prop::Num(v)) if *v >= 1.0 => *v as usize,
            _ => return Ok(None),
        };
        let get = |key: String| ch.props.get(&key);
        let num = |key: String| -> Result<f64, DataFileError> {
            match get(key.clone()) {
                Some(Prop::Num(v)) => Ok(*v),
                _ => Err(self.err(format!(
                    "channel `{}`: the scaling property {key} is missing or not a number; fix the channel's scaling in LabVIEW or export scaled values",
                    ch.name
                ))),
            }
        };
        let mut scales = Vec::with_capacity(n);
        for s in 0..n {
            let kind = match get(format!("NI_Scale[{s}]_Scale_Type")) {
                Some(Prop::Str(t)) => t.clone(),
                _ => {
                    return Err(self.err(format!(
                        "channel `{}`: NI_Scale[{s}]_Scale_Type is missing; fix the channel's scaling or export scaled values",
                        ch.name
                    )))
                }
            };
            let (scale, source_key) = match kind.as_str() {
                "Linear" => (
                    Scale::Polynomial(vec![
                        num(format!("NI_Scale[{s}]_Linear_Y_Intercept"))?,
                        num(format!("NI_Scale[{s}]_Linear_Slope"))?,
                    ]),
                    format!("NI_Scale[{s}]_Linear_Input_Source"),
                ),
                "Polynomial" => {
                    let m = num(format!("NI_Scale[{s}]_Polynomial_Coefficients_Size"))? as usize;
                    let coef = (0..m.min(64))
                        .map(|i| num(format!("NI_Scale[{s}]_Polynomial_Coefficients[{i}]")))
                        .collect::<Result<Vec<f64>, _>>()?;
                    (
                        Scale::Polynomial(coef),
                        format!("NI_Scale[{s}]_Polynomial_Input_Source"),
                    )
                }
                other => {
                    return Err(self.err(format!(
                        "channel `{}`: the scale NI_Scale[{s}] is of type `{other}`, which ambid does not apply (it applies Linear and Polynomial scales); export the channel with scaled values",
                        ch.name
                    )))
                }
            };
            let source = match get(source_key) {
                Some(Prop::Num(v)) if *v >= 0.0 && (*v as u64) < s as u64 => Some(*v as usize),
                _ => None,
            };
            scales.push((scale, source));
        }
        Ok(Some(Scaling { scales }))
    }

    /// The values `rows` of channel `k` as `f64`, scaled (module docs).
    pub(super) fn read(&mut self, k: usize, rows: Range<u64>) -> Result<Vec<f64>, DataFileError> {
        let ch = &self.channels[k];
        let dtype = ch.dtype.unwrap_or(DataType::F64);
        if !dtype.numeric() {
            return Err(self.err(format!(
                "channel `{}` holds {}, not numbers; select a numeric channel",
                ch.name,
                dtype.describe()
            )));
        }
        let len = ch.len();
        let rows = rows.start.min(len)..rows.end.min(len);
        let mut out = Vec::with_capacity((rows.end - rows.start) as usize);
        let runs = ch.runs.clone();
        let name = ch.name.clone();
        let mut buf = Vec::new();
        for run in &runs {
            let (a, b) = (run.start, run.start + run.len());
            if b <= rows.start || a >= rows.end {
                continue;
            }
            let Some(size) = run.dtype.size() else {
                return Err(self.err(format!("channel `{name}`: values without a fixed size")));
            };
            let lo = rows.start.max(a) - a;
            let hi = rows.end.min(b) - a;
            // chunk by chunk (one read per chunk, or one for a contiguous single-chunk run)
            let mut i = lo;
            while i < hi {
                let c = i / run.count;
                let j0 = i % run.count;
                let j1 = (hi - c * run.count).min(run.count);
                let n = j1 - j0;
                let at = run.first + c * run.chunk_step + j0 * run.stride;
                let span = (n - 1) * run.stride + size;
                buf.resize(span as usize, 0);
                self.file
                    .seek(SeekFrom::Start(at))
                    .and_then(|_| self.file.read_exact(&mut buf))
                    .map_err(|e| {
                        DataFileError::invalid(
                            &self.path,
                            format!("channel `{name}`: cannot read its values at byte {at} ({e}); the file may be truncated"),
                        )
                    })?;
                for v in 0..n {
                    let o = (v * run.stride) as usize;
                    out.push(decode(
                        &buf[o..o + size as usize],
                        run.dtype,
                        run.big_endian,
                    ));
                }
                i += n;
            }
        }
        if let Some(s) = self.scaling(k)? {
            for v in &mut out {
                *v = s.apply(*v);
            }
        }
        Ok(out)
    }
}

fn decode(b: &[u8], t: DataType, big: bool) -> f64 {
    macro_rules! n {
        ($ty:ty) => {{
            let mut a = [0u8; std::mem::size_of::<$ty>()];
            a.copy_from_slice(b);
            (if big {
                <$ty>::from_be_bytes(a)
            } else {
                <$ty>::from_le_bytes(a)
            }) as f64
        }};
    }
    match t {
        DataType::I8 => b[0] as i8 as f64,
        DataType::U8 | DataType::Bool => b[0] as f64,
        DataType::I16 => n!(i16),
        DataType::U16 => n!(u16),
        DataType::I32 => n!(i32),
        DataType::U32 => n!(u32),
        DataType::I64 => n!(i64),
        DataType::U64 => n!(u64),
        DataType::F32 => n!(f32),
        DataType::F64 => n!(f64),
        DataType::Other(_) => f64::NAN,
    }
}

/// One scale of a channel's scaling chain.
#[derive(Debug, Clone)]
enum Scale {
    /// $\sum_i c_i x^i$ (a linear scale is $c_0 + c_1 x$).
    Polynomial(Vec<f64>),
}

/// A channel's scales; the last one gives the scaled value, each takes its input from the raw
/// value or from an earlier scale.
#[derive(Debug, Clone)]
struct Scaling {
    scales: Vec<(Scale, Option<usize>)>,
}

impl Scaling {
    fn apply(&self, raw: f64) -> f64 {
        let mut vals: Vec<f64> = Vec::with_capacity(self.scales.len());
        for (scale, source) in &self.scales {
            let x = source.map_or(raw, |s| vals[s]);
            let Scale::Polynomial(c) = scale;
            let y = c.iter().rev().fold(0.0, |acc, ci| acc * x + ci);
            vals.push(y);
        }
        *vals.last().unwrap_or(&raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal TDMS writer for the layouts npTDMS does not write (interleaved, big-endian,
    /// interrupted segments); the files of real writers are tested in tests/data_files.rs.
    struct W {
        big: bool,
        out: Vec<u8>,
    }

    impl W {
        fn u32(&mut self, v: u32) {
            self.out.extend(if self.big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        fn u64(&mut self, v: u64) {
            self.out.extend(if self.big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        fn s(&mut self, s: &str) {
            self.u32(s.len() as u32);
            self.out.extend(s.as_bytes());
        }
    }

    /// An object of [`segment`]: path, `Some((type, count))` (type 0: reuse the previous
    /// index) or `None` (no data), f64 properties.
    type Object<'a> = (&'a str, Option<(u32, u64)>, &'a [(&'a str, f64)]);

    /// One segment: objects, raw bytes.
    fn segment(toc: u32, objects: &[Object], raw: &[u8], incomplete: bool) -> Vec<u8> {
        let big = toc & TOC_BIG_ENDIAN != 0;
        let mut m = W {
            big,
            out: Vec::new(),
        };
        m.u32(objects.len() as u32);
        for (p, ix, props) in objects {
            m.s(p);
            match ix {
                None => m.u32(0xFFFF_FFFF),
                Some((0, _)) => m.u32(0),
                Some((t, n)) => {
                    m.u32(20);
                    m.u32(*t);
                    m.u32(1);
                    m.u64(*n);
                }
            }
            m.u32(props.len() as u32);
            for (k, v) in props.iter() {
                m.s(k);
                m.u32(10);
                m.out.extend(if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                });
            }
        }
        let meta = if toc & TOC_META != 0 {
            m.out
        } else {
            Vec::new()
        };
        let mut w = W {
            big,
            out: b"TDSm".to_vec(),
        };
        w.out.extend(toc.to_le_bytes());
        w.u32(4713);
        w.u64(if incomplete {
            u64::MAX
        } else {
            (meta.len() + raw.len()) as u64
        });
        w.u64(meta.len() as u64);
        w.out.extend(meta);
        w.out.extend(raw);
        w.out
    }

    fn f64s(v: &[f64], big: bool) -> Vec<u8> {
        v.iter()
            .flat_map(|x| {
                if big {
                    x.to_be_bytes()
                } else {
                    x.to_le_bytes()
                }
            })
            .collect()
    }

    fn i16s(v: &[i16]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    fn write(name: &str, bytes: &[u8]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("ambid-tdms-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    const ALL: u32 = TOC_META | TOC_NEW_OBJ_LIST | TOC_RAW;

    #[test]
    fn contiguous_segments_with_reused_index_and_windows() {
        // segment 1: a (f64, 3 per chunk), b (i16, 3 per chunk), 2 chunks
        let a: Vec<f64> = (0..12).map(|k| k as f64 * 0.5).collect();
        let b: Vec<i16> = (0..12).map(|k| -k as i16 * 3).collect();
        let mut raw = Vec::new();
        for c in 0..2 {
            raw.extend(f64s(&a[3 * c..3 * c + 3], false));
            raw.extend(i16s(&b[3 * c..3 * c + 3]));
        }
        let mut file = segment(
            ALL,
            &[
                ("/", None, &[]),
                ("/'g'", None, &[]),
                ("/'g'/'a'", Some((10, 3)), &[("wf_increment", 1e-3)]),
                ("/'g'/'b'", Some((2, 3)), &[]),
            ],
            &raw,
            false,
        );
        // segment 2: same list, raw data only (no metadata): one chunk
        let mut raw2 = f64s(&a[6..9], false);
        raw2.extend(i16s(&b[6..9]));
        file.extend(segment(TOC_RAW, &[], &raw2, false));
        // segment 3: metadata with index reuse (0) for a and b, one chunk
        let mut raw3 = f64s(&a[9..12], false);
        raw3.extend(i16s(&b[9..12]));
        file.extend(segment(
            TOC_META | TOC_RAW,
            &[
                ("/'g'/'a'", Some((0, 0)), &[]),
                ("/'g'/'b'", Some((0, 0)), &[]),
            ],
            &raw3,
            false,
        ));
        let p = write("contig.tdms", &file);
        let mut t = TdmsFile::open(&p).unwrap();
        assert_eq!(t.names(), ["g/a", "g/b"]);
        assert_eq!(t.len(0), 12);
        assert_eq!(t.sample_time(0), Some(1e-3));
        assert_eq!(t.sample_time(1), None);
        assert_eq!(t.read(0, 0..12).unwrap(), a);
        let bf: Vec<f64> = b.iter().map(|&v| v as f64).collect();
        assert_eq!(t.read(1, 0..12).unwrap(), bf);
        // windows across chunk and segment borders
        for (lo, hi) in [(2, 7), (5, 6), (0, 1), (8, 12), (3, 3)] {
            assert_eq!(t.read(0, lo..hi).unwrap(), a[lo as usize..hi as usize]);
            assert_eq!(t.read(1, lo..hi).unwrap(), bf[lo as usize..hi as usize]);
        }
    }

    #[test]
    fn interleaved_big_endian_and_an_interrupted_segment() {
        let n = 5u64;
        let x: Vec<f64> = (0..n).map(|k| k as f64 + 0.25).collect();
        let y: Vec<f64> = (0..n).map(|k| -(k as f64)).collect();
        let mut raw = Vec::new();
        for k in 0..n as usize {
            raw.extend(f64s(&[x[k]], true));
            raw.extend(f64s(&[y[k]], true));
        }
        let toc = ALL | TOC_INTERLEAVED | TOC_BIG_ENDIAN;
        let mut file = segment(
            toc,
            &[
                ("/'g'/'x'", Some((10, n)), &[]),
                ("/'g'/'y'", Some((10, n)), &[]),
            ],
            &raw,
            false,
        );
        // an interrupted contiguous segment: declared 4 values each, only x's 4 and 1 of y
        let mut raw2 = f64s(&[10.0, 11.0, 12.0, 13.0], false);
        raw2.extend(f64s(&[-10.0], false));
        raw2.extend([1, 2, 3]); // a partial value
        file.extend(segment(
            ALL,
            &[
                ("/'g'/'x'", Some((10, 4)), &[]),
                ("/'g'/'y'", Some((10, 4)), &[]),
            ],
            &raw2,
            true,
        ));
        let p = write("inter.tdms", &file);
        let mut t = TdmsFile::open(&p).unwrap();
        let mut xa = x.clone();
        xa.extend([10.0, 11.0, 12.0, 13.0]);
        let mut ya = y.clone();
        ya.push(-10.0);
        assert_eq!(t.read(0, 0..100).unwrap(), xa);
        assert_eq!(t.read(1, 0..100).unwrap(), ya);
        assert_eq!(t.read(0, 1..3).unwrap(), x[1..3]);
    }

    #[test]
    fn damaged_files_name_the_problem() {
        let raw = f64s(&[1.0, 2.0], false);
        let good = segment(ALL, &[("/'g'/'a'", Some((10, 2)), &[])], &raw, false);
        let mut bad = good.clone();
        bad[3] = b'x';
        let e = TdmsFile::open(&write("tag.tdms", &bad))
            .unwrap_err()
            .to_string();
        assert!(e.contains("tag.tdms") && e.contains("TDSm"), "{e}");
        let cut = &good[..good.len() - 3];
        let e = TdmsFile::open(&write("cut.tdms", cut))
            .unwrap_err()
            .to_string();
        assert!(e.contains("truncated") && e.contains("segment 1"), "{e}");
        let e = TdmsFile::open(&write("short.tdms", &good[..10]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("lead-in"), "{e}");
        let mut two = good.clone();
        two.extend(&good[..20]);
        let e = TdmsFile::open(&write("two.tdms", &two))
            .unwrap_err()
            .to_string();
        assert!(e.contains("segment 2") && e.contains("truncated"), "{e}");
        // a string channel is listed, reading it says why not
        let mut m = W {
            big: false,
            out: Vec::new(),
        };
        m.u32(1);
        m.s("/'g'/'s'");
        m.u32(28);
        m.u32(0x20);
        m.u32(1);
        m.u64(2);
        m.u64(14); // two u32 end offsets and 6 bytes of text
        m.u32(0);
        let mut raw = Vec::new();
        raw.extend(2u32.to_le_bytes());
        raw.extend(6u32.to_le_bytes());
        raw.extend(b"ab");
        raw.extend(b"cdef");
        let mut f = b"TDSm".to_vec();
        f.extend(ALL.to_le_bytes());
        f.extend(4713u32.to_le_bytes());
        f.extend(((m.out.len() + raw.len()) as u64).to_le_bytes());
        f.extend((m.out.len() as u64).to_le_bytes());
        f.extend(m.out);
        f.extend(raw);
        let mut t = TdmsFile::open(&write("str.tdms", &f)).unwrap();
        assert_eq!(t.names(), ["g/s"]);
        assert!(!t.is_numeric(0));
        let e = t.read(0, 0..2).unwrap_err().to_string();
        assert!(e.contains("`g/s` holds strings"), "{e}");
    }

    #[test]
    fn object_paths_with_quotes_and_slashes() {
        assert_eq!(
            split_path("/'a''b'/'c/d'"),
            Some(vec!["a'b".to_string(), "c/d".to_string()])
        );
        assert_eq!(split_path("/"), Some(vec![]));
        assert_eq!(split_path("/'g'"), Some(vec!["g".to_string()]));
        assert_eq!(split_path("/g"), None);
        assert_eq!(split_path("/'g"), None);
    }

    #[test]
    fn linear_and_chained_polynomial_scales() {
        let s = Scaling {
            scales: vec![
                (Scale::Polynomial(vec![0.001, 2.0]), None),
                (Scale::Polynomial(vec![1.0, 0.0, 1.0]), Some(0)),
            ],
        };
        let x: f64 = 3.0;
        let l = 0.001 + 2.0 * x;
        assert_eq!(s.apply(x), 1.0 + l * l);
    }
}
