//! A minimal MATLAB Level 5 MAT-file encoder: real double matrices and char row vectors,
//! uncompressed, little-endian (what MATLAB's `save -v6` writes for such variables).
//!
//! Layout (MathWorks, "MAT-File Format", Level 5): a 128-byte header (116 bytes of text, 8 bytes
//! of subsystem offset, the version `0x0100` and the endian indicator `"IM"`), then one
//! `miMATRIX` data element per variable. Every data element is an 8-byte tag (`u32` type, `u32`
//! byte count) followed by its data padded to a multiple of 8 bytes. A matrix holds, in order,
//! the array flags (`miUINT32` ×2: class and flags, then 0), the dimensions (`miINT32`), the name
//! (`miINT8`) and the real part (`miDOUBLE` column by column, or for a char array `miUINT16`
//! code units when the text is ASCII, `miUTF8` otherwise).

use super::{ExportError, Result, Value, Var};

const MI_INT8: u32 = 1;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_DOUBLE: u32 = 9;
const MI_UTF8: u32 = 16;
const MI_MATRIX: u32 = 14;

const MX_CHAR_CLASS: u32 = 4;
const MX_DOUBLE_CLASS: u32 = 6;

/// Length of the descriptive text at the start of the header.
const HEADER_TEXT: usize = 116;

/// Pads `out` with zero bytes to a multiple of 8.
fn pad8(out: &mut Vec<u8>) {
    while out.len() % 8 != 0 {
        out.push(0);
    }
}

fn too_large(what: &str) -> ExportError {
    ExportError::TooLarge {
        what: what.to_string(),
    }
}

/// Appends one data element (tag, data, padding) to `out`.
fn element(out: &mut Vec<u8>, ty: u32, data: &[u8], what: &str) -> Result<()> {
    let n = u32::try_from(data.len()).map_err(|_| too_large(what))?;
    out.extend_from_slice(&ty.to_le_bytes());
    out.extend_from_slice(&n.to_le_bytes());
    out.extend_from_slice(data);
    pad8(out);
    Ok(())
}

/// The header: text padded with spaces, zero subsystem offset, version 0x0100, "IM".
fn header(text: &str) -> Vec<u8> {
    let mut out: Vec<u8> = text
        .bytes()
        .map(|b| if b.is_ascii_graphic() { b } else { b' ' })
        .take(HEADER_TEXT)
        .collect();
    out.resize(HEADER_TEXT, b' ');
    out.extend_from_slice(&[0; 8]);
    out.extend_from_slice(&0x0100u16.to_le_bytes());
    out.extend_from_slice(b"IM");
    out
}

/// The body of one `miMATRIX` element (everything after its tag).
fn matrix_body(name: &str, class: u32, dims: [usize; 2], data: (u32, Vec<u8>)) -> Result<Vec<u8>> {
    let mut body = Vec::new();
    let mut flags = Vec::with_capacity(8);
    flags.extend_from_slice(&class.to_le_bytes()); // no complex/global/logical flags
    flags.extend_from_slice(&0u32.to_le_bytes());
    element(&mut body, MI_UINT32, &flags, name)?;
    let mut dim_bytes = Vec::with_capacity(8);
    for d in dims {
        let d = i32::try_from(d).map_err(|_| too_large(name))?;
        dim_bytes.extend_from_slice(&d.to_le_bytes());
    }
    element(&mut body, MI_INT32, &dim_bytes, name)?;
    element(&mut body, MI_INT8, name.as_bytes(), name)?;
    element(&mut body, data.0, &data.1, name)?;
    Ok(body)
}

fn doubles(rows: usize, cols: usize, row_major: &[f64]) -> (u32, Vec<u8>) {
    let mut bytes = Vec::with_capacity(8 * row_major.len());
    for j in 0..cols {
        for i in 0..rows {
            bytes.extend_from_slice(&row_major[i * cols + j].to_le_bytes());
        }
    }
    (MI_DOUBLE, bytes)
}

/// Char data: ASCII text as `miUINT16` (the classic form every reader knows), other text as
/// `miUTF8` (what MATLAB since R14 and `scipy.io.savemat` write; scipy would decode `miUINT16`
/// with the system codec and garble non-ASCII characters).
fn char_data(s: &str) -> (u32, Vec<u8>) {
    if s.is_ascii() {
        let bytes = s.encode_utf16().flat_map(|u| u.to_le_bytes()).collect();
        (MI_UINT16, bytes)
    } else {
        (MI_UTF8, s.as_bytes().to_vec())
    }
}

/// Encodes the variables as a complete MAT file.
pub(super) fn encode(header_text: &str, vars: &[Var]) -> Result<Vec<u8>> {
    let mut out = header(header_text);
    for v in vars {
        let body = match &v.value {
            Value::Matrix { rows, cols, data } => matrix_body(
                v.name,
                MX_DOUBLE_CLASS,
                [*rows, *cols],
                doubles(*rows, *cols, data),
            )?,
            Value::Vector(p) => matrix_body(
                v.name,
                MX_DOUBLE_CLASS,
                [1, p.len()],
                doubles(1, p.len(), p),
            )?,
            Value::Scalar(x) => matrix_body(v.name, MX_DOUBLE_CLASS, [1, 1], doubles(1, 1, &[*x]))?,
            Value::Text(s) => {
                // MATLAB's char is UTF-16: the length counts UTF-16 code units; '' is 0×0
                let units = s.encode_utf16().count();
                let dims = if units == 0 { [0, 0] } else { [1, units] };
                matrix_body(v.name, MX_CHAR_CLASS, dims, char_data(s))?
            }
        };
        element(&mut out, MI_MATRIX, &body, v.name)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn elements_are_padded_to_8_bytes() {
        let mut out = Vec::new();
        element(&mut out, MI_INT8, b"abc", "x").unwrap();
        assert_eq!(out.len(), 16);
        assert_eq!(&out[..8], &[1, 0, 0, 0, 3, 0, 0, 0]);
        assert_eq!(&out[8..], b"abc\0\0\0\0\0");
        let mut out = Vec::new();
        element(&mut out, MI_INT8, b"12345678", "x").unwrap();
        assert_eq!(out.len(), 16);
        let mut out = Vec::new();
        element(&mut out, MI_INT8, b"", "x").unwrap();
        assert_eq!(out.len(), 8);
    }

    #[test]
    fn header_is_128_bytes() {
        let h = header("MATLAB 5.0 MAT-file, test\n");
        assert_eq!(h.len(), 128);
        assert!(h.starts_with(b"MATLAB 5.0 MAT-file, test "));
        assert_eq!(&h[124..], &[0x00, 0x01, b'I', b'M']);
        assert_eq!(header(&"x".repeat(300)).len(), 128);
    }

    #[test]
    fn scalar_layout() {
        let vars = [Var {
            name: "Ts",
            value: Value::Scalar(0.5),
        }];
        let out = encode("MATLAB 5.0 MAT-file", &vars).unwrap();
        let m = &out[128..];
        // miMATRIX tag: flags 16 + dims 16 + name 16 + data 16 = 64 bytes
        assert_eq!(&m[..8], &[14, 0, 0, 0, 64, 0, 0, 0]);
        assert_eq!(m.len(), 72);
        assert_eq!(&m[8..24], &[6, 0, 0, 0, 8, 0, 0, 0, 6, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(
            &m[24..40],
            &[5, 0, 0, 0, 8, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]
        );
        assert_eq!(&m[40..56], b"\x01\0\0\0\x02\0\0\0Ts\0\0\0\0\0\0");
        assert_eq!(&m[56..64], &[9, 0, 0, 0, 8, 0, 0, 0]);
        assert_eq!(&m[64..72], &0.5f64.to_le_bytes());
    }

    #[test]
    fn matrices_are_column_major_and_text_utf16() {
        let vars = [
            Var {
                name: "M",
                value: Value::Matrix {
                    rows: 2,
                    cols: 2,
                    data: vec![1.0, 2.0, 3.0, 4.0],
                },
            },
            Var {
                name: "s",
                value: Value::Text("ab".into()),
            },
            Var {
                name: "e",
                value: Value::Text(String::new()),
            },
        ];
        let out = encode("MATLAB 5.0 MAT-file", &vars).unwrap();
        assert_eq!(out.len() % 8, 0);
        let m = &out[128..];
        let data = &m[64..96];
        let vals: Vec<f64> = data
            .chunks(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert_eq!(vals, [1.0, 3.0, 2.0, 4.0]);
        let s = &m[96..];
        assert_eq!(&s[8 + 8..8 + 12], &[4, 0, 0, 0]); // mxCHAR_CLASS
        assert_eq!(&s[8 + 32..8 + 40], b"\x01\0\0\0\x01\0\0\0");
        assert_eq!(&s[8 + 48..8 + 56], &[4, 0, 0, 0, 4, 0, 0, 0]); // miUINT16, 4 bytes
        assert_eq!(&s[8 + 56..8 + 64], b"a\0b\0\0\0\0\0");
        let e = &s[72..];
        assert_eq!(&e[8 + 24..8 + 32], &[0; 8]); // 0×0
        assert_eq!(&e[8 + 48..8 + 56], &[4, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(e.len(), 8 + 56);
    }

    #[test]
    fn non_ascii_text_is_utf8_with_utf16_length() {
        assert_eq!(char_data("ab"), (MI_UINT16, b"a\0b\0".to_vec()));
        assert_eq!(char_data("µ"), (MI_UTF8, "µ".as_bytes().to_vec()));
        let vars = [Var {
            name: "s",
            value: Value::Text("µ😀".into()),
        }];
        let out = encode("MATLAB 5.0 MAT-file", &vars).unwrap();
        let m = &out[128..];
        assert_eq!(&m[32..40], &[1, 0, 0, 0, 3, 0, 0, 0]); // 1×3 UTF-16 code units
        assert_eq!(&m[56..64], &[16, 0, 0, 0, 6, 0, 0, 0]); // miUTF8, 6 bytes
        assert_eq!(&m[64..70], "µ😀".as_bytes());
    }
}
