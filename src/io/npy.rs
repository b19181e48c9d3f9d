//! NPY (NumPy array file) reading and writing: the one NPY codec of the crate, used for the
//! training data (graph records, SDF samples, surface points, codebooks) and for users' point
//! clouds.
//!
//! Why it exists: NPY lets the data be inspected with NumPy without a parser dependency. The
//! writer makes version 1.0 headers, `<f4`, C order, the data at a multiple of 64 bytes. The
//! reader trusts nothing in the file: the header dict is parsed as the Python literal it is
//! (bounded depth), versions 1.0–3.0, `<f4`, `>f4`, `<f8`, `>f8`, C or Fortran order, and every
//! size is checked before anything is allocated or read.

use std::path::Path;

use super::{FormatError, snippet};

/// The magic bytes every NPY file starts with.
pub const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// A malformed or truncated NPY file.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    /// The header or the data contradicts the format; the message says where.
    #[error("{0}")]
    Malformed(String),
    /// The file ends before `expected_bytes`.
    #[error("truncated: expected at least {expected_bytes} bytes, got {got_bytes}")]
    Truncated {
        expected_bytes: u64,
        got_bytes: usize,
    },
}

fn mal(detail: impl Into<String>) -> NpyError {
    NpyError::Malformed(detail.into())
}

/// The element type of an NPY array physnap reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dtype {
    F32,
    F64,
}

impl Dtype {
    fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F64 => 8,
        }
    }

    fn decode(self, b: &[u8], big: bool) -> Option<f32> {
        Some(match self {
            Dtype::F32 => {
                let a = *b.first_chunk::<4>()?;
                if big {
                    f32::from_be_bytes(a)
                } else {
                    f32::from_le_bytes(a)
                }
            }
            Dtype::F64 => {
                let a = *b.first_chunk::<8>()?;
                (if big {
                    f64::from_be_bytes(a)
                } else {
                    f64::from_le_bytes(a)
                }) as f32
            }
        })
    }
}

/// A parsed NPY header.
#[derive(Debug)]
pub struct Header {
    pub dtype: Dtype,
    pub big_endian: bool,
    pub fortran_order: bool,
    /// The `shape` entry as written (a tuple of ints in a valid file).
    pub shape: Py,
    /// Byte offset of the first element.
    pub data_start: usize,
}

/// Parse the header of `bytes`, checking that it fits inside the file.
pub fn parse_header(bytes: &[u8]) -> Result<Header, NpyError> {
    let total = bytes.len();
    if !bytes.starts_with(NPY_MAGIC) {
        return Err(mal(format!(
            "missing the '\\x93NUMPY' magic (file starts with '{}')",
            snippet(&bytes[..total.min(8)])
        )));
    }
    let truncated = |expected_bytes: u64| NpyError::Truncated {
        expected_bytes,
        got_bytes: total,
    };
    let (Some(&major), Some(&minor)) = (bytes.get(6), bytes.get(7)) else {
        return Err(truncated(10));
    };
    let (len_size, header_start) = match (major, minor) {
        (1, 0) => (2usize, 10usize),
        (2 | 3, 0) => (4, 12),
        _ => {
            return Err(mal(format!(
                "unsupported format version {major}.{minor} (expected 1.0, 2.0 or 3.0)"
            )));
        }
    };
    let Some(len_bytes) = bytes.get(8..8 + len_size) else {
        return Err(truncated(header_start as u64));
    };
    let header_len = len_bytes
        .iter()
        .rev()
        .fold(0u64, |acc, &b| (acc << 8) | u64::from(b));
    let data_start = header_start as u64 + header_len;
    if data_start > total as u64 {
        return Err(truncated(data_start));
    }
    let data_start = data_start as usize; // <= total
    let raw_header = &bytes[header_start..data_start];
    // Versions 1 and 2 are latin-1, version 3 is UTF-8.
    let header: String = if major == 3 {
        String::from_utf8_lossy(raw_header).into_owned()
    } else {
        raw_header.iter().map(|&b| char::from(b)).collect()
    };
    let mut parser = PyParser {
        s: header.as_bytes(),
        pos: 0,
    };
    let dict = match parser.peek() {
        Some(b'{') => parser.dict(0),
        _ => Err(SyntaxError(format!(
            "expected a dict, {}",
            parser.unexpected()
        ))),
    }
    .and_then(|d| match parser.peek() {
        None => Ok(d),
        Some(_) => Err(SyntaxError(format!(
            "after the dict: {}",
            parser.unexpected()
        ))),
    })
    .map_err(|e| mal(format!("header dict: {e}")))?;
    let Py::Dict(mut entries) = dict else {
        return Err(mal("header is not a dict"));
    };
    let mut take = |key: &str| {
        entries
            .iter()
            .rposition(|(k, _)| matches!(k, Py::Str(s) if s == key))
            .map(|i| entries.swap_remove(i).1)
            .ok_or_else(|| mal(format!("header has no '{key}' key")))
    };
    let descr = take("descr")?;
    let fortran = take("fortran_order")?;
    let shape = take("shape")?;
    let (dtype, big_endian) = match &descr {
        Py::Str(s) if s == "<f4" => (Dtype::F32, false),
        Py::Str(s) if s == ">f4" => (Dtype::F32, true),
        Py::Str(s) if s == "<f8" => (Dtype::F64, false),
        Py::Str(s) if s == ">f8" => (Dtype::F64, true),
        other => {
            return Err(mal(format!(
                "header 'descr' is {other}; expected '<f4', '<f8', '>f4' or '>f8' \
                 (float32 or float64)"
            )));
        }
    };
    let fortran_order = match fortran {
        Py::Bool(b) => b,
        other => {
            return Err(mal(format!(
                "header 'fortran_order' is {other}; expected True or False"
            )));
        }
    };
    Ok(Header {
        dtype,
        big_endian,
        fortran_order,
        shape,
        data_start,
    })
}

/// The `rows × cols` elements after `header`, as f32 in C (row-major) order, whatever the file's
/// order; the caller has checked the shape and bounded `rows`.
pub fn read_data(
    bytes: &[u8],
    header: &Header,
    rows: usize,
    cols: usize,
) -> Result<Vec<f32>, NpyError> {
    let total = bytes.len();
    let size = header.dtype.size();
    let truncated = |expected_bytes| NpyError::Truncated {
        expected_bytes,
        got_bytes: total,
    };
    let end = (header.data_start as u64).saturating_add(
        (rows as u64)
            .saturating_mul(cols as u64)
            .saturating_mul(size as u64),
    );
    if end > total as u64 {
        return Err(truncated(end));
    }
    let data = &bytes[header.data_start..end as usize];
    let mut out = Vec::with_capacity(rows * cols);
    for i in 0..rows {
        for j in 0..cols {
            let k = if header.fortran_order {
                j * rows + i
            } else {
                i * cols + j
            };
            let v = data
                .get(k * size..)
                .and_then(|b| header.dtype.decode(b, header.big_endian))
                .ok_or_else(|| truncated(end))?;
            out.push(v);
        }
    }
    Ok(out)
}

/// Serialise a `rows × cols` f32 array.
pub fn to_bytes(rows: usize, cols: usize, data: &[f32]) -> Vec<u8> {
    debug_assert_eq!(rows * cols, data.len());
    let dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    // magic (6) + version (2) + header length (2) + header, ending in '\n', a multiple of 64.
    let unpadded = 10 + dict.len() + 1;
    let total = unpadded.div_ceil(64) * 64;
    let mut header = dict.into_bytes();
    header.resize(total - 10 - 1, b' ');
    header.push(b'\n');
    let mut out = Vec::with_capacity(total + data.len() * 4);
    out.extend_from_slice(NPY_MAGIC);
    out.extend_from_slice(&[1, 0]);
    // The dict is < 100 bytes, so its length always fits the u16 of version 1.0.
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(&header);
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Parse a 1-D or 2-D float array: `(rows, cols, data)` (a 1-D array is one column).
pub fn from_bytes(bytes: &[u8]) -> Result<(usize, usize, Vec<f32>), NpyError> {
    let header = parse_header(bytes)?;
    let dims = match &header.shape {
        Py::Tuple(dims) => dims
            .iter()
            .map(|d| match d {
                Py::Int(n) => usize::try_from(*n).ok(),
                _ => None,
            })
            .collect::<Option<Vec<usize>>>(),
        _ => None,
    };
    let (rows, cols) = match dims.as_deref() {
        Some(&[r, c]) => (r, c),
        Some(&[r]) => (r, 1),
        _ => {
            return Err(mal(format!(
                "header 'shape' is {}; expected (rows, cols) or (rows,)",
                header.shape
            )));
        }
    };
    // `read_data` checks the size against the file before it allocates.
    let data = read_data(bytes, &header, rows, cols)?;
    Ok((rows, cols, data))
}

/// Write a `rows × cols` f32 array to `path`.
pub fn write(path: &Path, rows: usize, cols: usize, data: &[f32]) -> Result<(), FormatError> {
    std::fs::write(path, to_bytes(rows, cols, data)).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Read a 1-D or 2-D float array from `path`.
pub fn read(path: &Path) -> Result<(usize, usize, Vec<f32>), FormatError> {
    let bytes = std::fs::read(path).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })?;
    from_bytes(&bytes).map_err(|e| FormatError::Malformed {
        what: "NPY array",
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

// ---------------------------------------------------------------------------------------------
// The header dict: a Python literal

/// A Python literal as found in an NPY header.
#[derive(Debug, PartialEq)]
pub enum Py {
    Str(String),
    Bool(bool),
    None,
    Int(i128),
    Tuple(Vec<Py>),
    List(Vec<Py>),
    Dict(Vec<(Py, Py)>),
}

impl std::fmt::Display for Py {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let seq = |f: &mut std::fmt::Formatter<'_>, items: &[Py]| -> std::fmt::Result {
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    f.write_str(", ")?;
                }
                write!(f, "{item}")?;
            }
            Ok(())
        };
        match self {
            Py::Str(s) => write!(f, "'{}'", snippet(s.as_bytes())),
            Py::Bool(true) => f.write_str("True"),
            Py::Bool(false) => f.write_str("False"),
            Py::None => f.write_str("None"),
            Py::Int(i) => write!(f, "{i}"),
            Py::Tuple(items) => {
                f.write_str("(")?;
                seq(f, items)?;
                f.write_str(if items.len() == 1 { ",)" } else { ")" })
            }
            Py::List(items) => {
                f.write_str("[")?;
                seq(f, items)?;
                f.write_str("]")
            }
            Py::Dict(_) => f.write_str("{...}"),
        }
    }
}

/// What is wrong with an NPY header's Python literal, and where.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub(crate) struct SyntaxError(pub(crate) String);

/// Recursive-descent parser for the Python literal subset numpy writes in NPY headers.
pub(crate) struct PyParser<'a> {
    pub(crate) s: &'a [u8],
    pub(crate) pos: usize,
}

impl PyParser<'_> {
    pub(crate) const MAX_DEPTH: usize = 16;

    pub(crate) fn skip_ws(&mut self) {
        while self.s.get(self.pos).is_some_and(u8::is_ascii_whitespace) {
            self.pos += 1;
        }
    }

    pub(crate) fn peek(&mut self) -> Option<u8> {
        self.skip_ws();
        self.s.get(self.pos).copied()
    }

    pub(crate) fn unexpected(&self) -> SyntaxError {
        match self.s.get(self.pos) {
            Some(_) => {
                let near = &self.s[self.pos..(self.pos + 12).min(self.s.len())];
                let c = String::from_utf8_lossy(near).chars().next().unwrap_or('?');
                SyntaxError(format!(
                    "unexpected '{}' at offset {} (near '{}')",
                    c.escape_debug(),
                    self.pos,
                    snippet(near)
                ))
            }
            None => SyntaxError("unexpected end of header".to_string()),
        }
    }

    pub(crate) fn value(&mut self, depth: usize) -> Result<Py, SyntaxError> {
        if depth > Self::MAX_DEPTH {
            return Err(SyntaxError(format!(
                "nested deeper than {}",
                Self::MAX_DEPTH
            )));
        }
        match self.peek() {
            Some(q @ (b'\'' | b'"')) => self.string(q),
            Some(b'(') => self.seq(b')', depth).map(Py::Tuple),
            Some(b'[') => self.seq(b']', depth).map(Py::List),
            Some(b'{') => self.dict(depth),
            Some(b'-' | b'+' | b'0'..=b'9') => self.int(),
            Some(b'A'..=b'Z' | b'a'..=b'z') => {
                let start = self.pos;
                while self.s.get(self.pos).is_some_and(u8::is_ascii_alphanumeric) {
                    self.pos += 1;
                }
                match &self.s[start..self.pos] {
                    b"True" => Ok(Py::Bool(true)),
                    b"False" => Ok(Py::Bool(false)),
                    b"None" => Ok(Py::None),
                    word => Err(SyntaxError(format!(
                        "unknown name '{}' at offset {start}",
                        snippet(word)
                    ))),
                }
            }
            _ => Err(self.unexpected()),
        }
    }

    pub(crate) fn string(&mut self, quote: u8) -> Result<Py, SyntaxError> {
        let start = self.pos;
        self.pos += 1;
        let mut out = Vec::new();
        loop {
            match self.s.get(self.pos) {
                None => {
                    return Err(SyntaxError(format!(
                        "unterminated string starting at offset {start}"
                    )));
                }
                Some(&b) if b == quote => {
                    self.pos += 1;
                    return Ok(Py::Str(String::from_utf8_lossy(&out).into_owned()));
                }
                Some(b'\\') => {
                    match self.s.get(self.pos + 1) {
                        Some(&c @ (b'\\' | b'\'' | b'"')) => out.push(c),
                        Some(b'n') => out.push(b'\n'),
                        Some(&c) => out.extend_from_slice(&[b'\\', c]),
                        None => {
                            return Err(SyntaxError(format!(
                                "unterminated string starting at offset {start}"
                            )));
                        }
                    }
                    self.pos += 2;
                }
                Some(&b) => {
                    out.push(b);
                    self.pos += 1;
                }
            }
        }
    }

    pub(crate) fn int(&mut self) -> Result<Py, SyntaxError> {
        let start = self.pos;
        if matches!(self.s.get(self.pos), Some(b'-' | b'+')) {
            self.pos += 1;
        }
        while self.s.get(self.pos).is_some_and(u8::is_ascii_digit) {
            self.pos += 1;
        }
        let text = &self.s[start..self.pos];
        // Python 2 era numpy wrote long integers as `3L`.
        if matches!(self.s.get(self.pos), Some(b'L' | b'l')) {
            self.pos += 1;
        }
        std::str::from_utf8(text)
            .ok()
            .and_then(|t| t.parse::<i128>().ok())
            .map(Py::Int)
            .ok_or_else(|| {
                SyntaxError(format!(
                    "'{}' at offset {start} is not a valid integer",
                    snippet(text)
                ))
            })
    }

    pub(crate) fn seq(&mut self, close: u8, depth: usize) -> Result<Vec<Py>, SyntaxError> {
        self.pos += 1; // opening bracket
        let mut items = Vec::new();
        loop {
            if self.peek() == Some(close) {
                self.pos += 1;
                return Ok(items);
            }
            items.push(self.value(depth + 1)?);
            match self.peek() {
                Some(b',') => self.pos += 1,
                Some(c) if c == close => {}
                _ => return Err(self.unexpected()),
            }
        }
    }

    pub(crate) fn dict(&mut self, depth: usize) -> Result<Py, SyntaxError> {
        self.pos += 1; // '{'
        let mut entries = Vec::new();
        loop {
            if self.peek() == Some(b'}') {
                self.pos += 1;
                return Ok(Py::Dict(entries));
            }
            let key = self.value(depth + 1)?;
            if self.peek() != Some(b':') {
                return Err(self.unexpected());
            }
            self.pos += 1;
            let value = self.value(depth + 1)?;
            entries.push((key, value));
            match self.peek() {
                Some(b',') => self.pos += 1,
                Some(b'}') => {}
                _ => return Err(self.unexpected()),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn round_trip_and_alignment() {
        let data: Vec<f32> = (0..12).map(|v| v as f32 * 0.5 - 1.0).collect();
        let b = super::to_bytes(3, 4, &data);
        let hlen = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + hlen) % 64, 0);
        assert_eq!(super::from_bytes(&b).unwrap(), (3, 4, data));
        assert!(
            super::from_bytes(&b[..b.len() - 1])
                .unwrap_err()
                .to_string()
                .contains("truncated")
        );
        assert!(super::from_bytes(b"hello world").is_err());
    }
}
