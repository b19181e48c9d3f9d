//! NPY point clouds: an (N, 3) float array, any float width and byte order, parsed without
//! trusting the header.

#[allow(unused_imports)]
use super::*;
use std::fmt::Write as _;
use std::fs;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

// ---------------------------------------------------------------------------------------------
// NPY

pub(crate) const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// A Python literal as found in an NPY header.
#[derive(Debug, PartialEq)]
pub(crate) enum Py {
    Str(String),
    Bool(bool),
    None,
    Int(i128),
    Tuple(Vec<Py>),
    List(Vec<Py>),
    Dict(Vec<(Py, Py)>),
}

impl std::fmt::Display for Py {
    pub(crate) fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
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

    pub(crate) fn unexpected(&self) -> String {
        match self.s.get(self.pos) {
            Some(_) => {
                let near = &self.s[self.pos..(self.pos + 12).min(self.s.len())];
                let c = String::from_utf8_lossy(near).chars().next().unwrap_or('?');
                format!(
                    "unexpected '{}' at offset {} (near '{}')",
                    c.escape_debug(),
                    self.pos,
                    snippet(near)
                )
            }
            None => "unexpected end of header".to_string(),
        }
    }

    pub(crate) fn value(&mut self, depth: usize) -> Result<Py, String> {
        if depth > Self::MAX_DEPTH {
            return Err(format!("nested deeper than {}", Self::MAX_DEPTH));
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
                    word => Err(format!(
                        "unknown name '{}' at offset {start}",
                        snippet(word)
                    )),
                }
            }
            _ => Err(self.unexpected()),
        }
    }

    pub(crate) fn string(&mut self, quote: u8) -> Result<Py, String> {
        let start = self.pos;
        self.pos += 1;
        let mut out = Vec::new();
        loop {
            match self.s.get(self.pos) {
                None => return Err(format!("unterminated string starting at offset {start}")),
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
                            return Err(format!("unterminated string starting at offset {start}"));
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

    pub(crate) fn int(&mut self) -> Result<Py, String> {
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
                format!(
                    "'{}' at offset {start} is not a valid integer",
                    snippet(text)
                )
            })
    }

    pub(crate) fn seq(&mut self, close: u8, depth: usize) -> Result<Vec<Py>, String> {
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

    pub(crate) fn dict(&mut self, depth: usize) -> Result<Py, String> {
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

pub(crate) fn npy_read(bytes: &[u8], limits: &Limits) -> Result<Vec<[f32; 3]>, PointCloudError> {
    let total = bytes.len();
    if !bytes.starts_with(NPY_MAGIC) {
        return Err(mal(
            NPY,
            format!(
                "missing the '\\x93NUMPY' magic (file starts with '{}')",
                snippet(&bytes[..total.min(8)])
            ),
        ));
    }
    let (Some(&major), Some(&minor)) = (bytes.get(6), bytes.get(7)) else {
        return Err(truncated(NPY, 10, total));
    };
    let (len_size, header_start) = match (major, minor) {
        (1, 0) => (2usize, 10usize),
        (2 | 3, 0) => (4, 12),
        _ => {
            return Err(mal(
                NPY,
                format!("unsupported format version {major}.{minor} (expected 1.0, 2.0 or 3.0)"),
            ));
        }
    };
    let Some(len_bytes) = bytes.get(8..8 + len_size) else {
        return Err(truncated(NPY, header_start as u64, total));
    };
    let header_len = len_bytes
        .iter()
        .rev()
        .fold(0u64, |acc, &b| (acc << 8) | u64::from(b));
    let data_start = header_start as u64 + header_len;
    if data_start > total as u64 {
        return Err(truncated(NPY, data_start, total));
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
        _ => Err(format!("expected a dict, {}", parser.unexpected())),
    }
    .and_then(|d| match parser.peek() {
        None => Ok(d),
        Some(_) => Err(format!("after the dict: {}", parser.unexpected())),
    })
    .map_err(|e| mal(NPY, format!("header dict: {e}")))?;
    let Py::Dict(entries) = dict else {
        return Err(mal(NPY, "header is not a dict"));
    };
    let get = |key: &str| {
        entries
            .iter()
            .rev()
            .find(|(k, _)| matches!(k, Py::Str(s) if s == key))
            .map(|(_, v)| v)
            .ok_or_else(|| mal(NPY, format!("header has no '{key}' key")))
    };
    let descr = get("descr")?;
    let (ty, big) = match descr {
        Py::Str(s) if s == "<f4" => (Scalar::F32, false),
        Py::Str(s) if s == ">f4" => (Scalar::F32, true),
        Py::Str(s) if s == "<f8" => (Scalar::F64, false),
        Py::Str(s) if s == ">f8" => (Scalar::F64, true),
        other => {
            return Err(mal(
                NPY,
                format!(
                    "header 'descr' is {other}; expected '<f4', '<f8', '>f4' or '>f8' \
                     (float32 or float64)"
                ),
            ));
        }
    };
    let fortran = match get("fortran_order")? {
        Py::Bool(b) => *b,
        other => {
            return Err(mal(
                NPY,
                format!("header 'fortran_order' is {other}; expected True or False"),
            ));
        }
    };
    let shape = get("shape")?;
    let n = match shape {
        Py::Tuple(dims) => match dims[..] {
            [Py::Int(n), Py::Int(3)] if n >= 0 => n,
            _ => {
                return Err(mal(
                    NPY,
                    format!("header 'shape' is {shape}; expected (N, 3)"),
                ));
            }
        },
        other => {
            return Err(mal(
                NPY,
                format!("header 'shape' is {other}; expected a tuple (N, 3)"),
            ));
        }
    };
    let count = check_count(u64::try_from(n).unwrap_or(u64::MAX), limits)?;
    let size = ty.size();
    let end = (data_start as u64).saturating_add((count as u64).saturating_mul(3 * size as u64));
    if end > total as u64 {
        return Err(truncated(NPY, end, total));
    }
    let data = &bytes[data_start..end as usize];
    let mut points = Vec::with_capacity(count);
    for i in 0..count {
        let mut p = [0f32; 3];
        for (axis, v) in p.iter_mut().enumerate() {
            let k = if fortran {
                axis * count + i
            } else {
                i * 3 + axis
            };
            *v = data
                .get(k * size..)
                .and_then(|b| ty.decode(b, big))
                .ok_or_else(|| truncated(NPY, end, total))?;
        }
        points.push(p);
    }
    Ok(points)
}

pub(crate) fn npy_write(points: &[[f32; 3]]) -> Vec<u8> {
    let mut header = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, 3), }}",
        points.len()
    );
    // magic (6) + version (2) + header length (2) + header, ending in '\n', a multiple of 64.
    let unpadded = 10 + header.len() + 1;
    header.extend(std::iter::repeat_n(' ', (64 - unpadded % 64) % 64));
    header.push('\n');
    // The dict is < 100 bytes, so its length always fits the u16 of version 1.0.
    let header_len = header.len() as u16;
    let mut out = Vec::with_capacity(10 + header.len() + points.len() * 12);
    out.extend_from_slice(NPY_MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&header_len.to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for p in points {
        for v in p {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}
