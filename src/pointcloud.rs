//! Point-cloud files: PLY (ascii and binary), NPY and JSON readers and writers.
//!
//! Why it exists: physnap takes a partial point cloud of an object (object frame, metres) and
//! generates an articulated 3D model. The data pipeline writes scans with this module, the CLI
//! reads user clouds with it, and the HTTP/gRPC service will reuse the same readers for
//! uploads. So the readers are built for hostile input: they never panic, never allocate from a
//! header's claims before checking them against the [`Limits`] and against the bytes actually
//! present, and every error names what is wrong (the field or header line, the limit, the
//! value) and has a stable machine-readable kind ([`PointCloudError::error_type`]).
//!
//! Formats:
//! - **PLY**: read in any encoding (`ascii`, `binary_little_endian`, `binary_big_endian`);
//!   the `vertex` element must have scalar `x`, `y`, `z` properties (any order, any scalar
//!   type); other vertex properties and other elements are skipped. [`Format::Ply`] writes
//!   binary little-endian `float` x, y, z; [`Format::PlyAscii`] writes ascii.
//! - **NPY**: versions 1.0, 2.0 and 3.0, `descr` `<f4`, `>f4`, `<f8` or `>f8`, C or Fortran
//!   order, shape `(N, 3)`. Written as version 1.0, `<f4`, data aligned to 64 bytes.
//! - **JSON**: `[[x, y, z], ...]` or `{"points": [[x, y, z], ...], ...}` (other keys ignored).
//!   Written as compact `{"points":[[x,y,z],...]}`; every written number reads back to the
//!   same `f32` bit for bit.
//!
//! Every reader ends with [`PointCloud::validate`], so a cloud that comes back from a reader
//! has between `min_points` and `max_points` points, all finite.

use std::collections::HashSet;
use std::fmt::Write as _;
use std::fs;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A point cloud in object coordinates (metres). Invariant after `validate`: 1..=max points, all finite.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// The points, `[x, y, z]` each.
    pub points: Vec<[f32; 3]>,
}

/// A point-cloud file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// PLY. Written as binary little-endian; read in any PLY encoding.
    Ply,
    /// PLY, written as ascii; read in any PLY encoding (same reader as [`Format::Ply`]).
    PlyAscii,
    /// NumPy `.npy`, an `(N, 3)` float array.
    Npy,
    /// JSON, `{"points": [[x, y, z], ...]}` or a bare `[[x, y, z], ...]`.
    Json,
}

impl Format {
    /// From a file extension: .ply, .npy, .json (case-insensitive). None otherwise.
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?;
        if ext.eq_ignore_ascii_case("ply") {
            Some(Format::Ply)
        } else if ext.eq_ignore_ascii_case("npy") {
            Some(Format::Npy)
        } else if ext.eq_ignore_ascii_case("json") {
            Some(Format::Json)
        } else {
            None
        }
    }
}

/// Why a point cloud could not be read, written or accepted.
#[derive(Debug, thiserror::Error)]
pub enum PointCloudError {
    /// The file system refused (open, read, write, fsync, rename).
    #[error("I/O error on '{}': {source}", path.display())]
    Io {
        /// The file the operation was on.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The path's extension names no supported format.
    #[error(
        "cannot tell the point-cloud format of '{}': expected extension .ply, .npy or .json",
        path.display()
    )]
    UnknownFormat {
        /// The offending path.
        path: PathBuf,
    },
    /// The bytes do not follow the format; `detail` names the header line, field or index.
    #[error("invalid {format}: {detail}")]
    Malformed {
        /// `"PLY"`, `"NPY"` or `"JSON"`.
        format: &'static str,
        /// What is wrong, where, and the offending value.
        detail: String,
    },
    /// The header promises more data than the input holds.
    #[error("truncated {format}: need at least {expected_bytes} bytes, got {got_bytes}")]
    Truncated {
        /// `"PLY"` or `"NPY"`.
        format: &'static str,
        /// Bytes the whole input needs to hold what its header claims.
        expected_bytes: u64,
        /// Bytes the input has.
        got_bytes: u64,
    },
    /// A coordinate is NaN or infinite (or, from JSON, outside the `f32` range).
    #[error("point {index} has a non-finite {} coordinate ({value})", axis_name(*.axis))]
    NonFinite {
        /// Index of the point.
        index: usize,
        /// 0 = x, 1 = y, 2 = z.
        axis: usize,
        /// The offending value.
        value: f32,
    },
    /// The cloud has no points.
    #[error("point cloud is empty (0 points, at least 1 required)")]
    Empty,
    /// Fewer points than [`Limits::min_points`].
    #[error("too few points: {count} (minimum {min})")]
    TooFew {
        /// Points in the cloud.
        count: usize,
        /// The limit.
        min: usize,
    },
    /// More points than [`Limits::max_points`]. `count` is a `u64` because it may be a
    /// header's claim that does not fit a `usize`.
    #[error("too many points: {count} (limit {max})")]
    TooMany {
        /// Points in the cloud, or claimed by its header.
        count: u64,
        /// The limit.
        max: usize,
    },
}

fn axis_name(axis: usize) -> &'static str {
    match axis {
        0 => "x",
        1 => "y",
        2 => "z",
        _ => "unknown-axis",
    }
}

impl PointCloudError {
    /// Stable machine-readable kind: "io", "unknown_format", "malformed", "truncated",
    /// "non_finite", "empty", "too_few", "too_many".
    pub fn error_type(&self) -> &'static str {
        match self {
            PointCloudError::Io { .. } => "io",
            PointCloudError::UnknownFormat { .. } => "unknown_format",
            PointCloudError::Malformed { .. } => "malformed",
            PointCloudError::Truncated { .. } => "truncated",
            PointCloudError::NonFinite { .. } => "non_finite",
            PointCloudError::Empty => "empty",
            PointCloudError::TooFew { .. } => "too_few",
            PointCloudError::TooMany { .. } => "too_many",
        }
    }
}

/// Limits applied by readers and `validate`.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Fewest points accepted (an empty cloud is always rejected).
    pub min_points: usize,
    /// Most points accepted; readers check a header's count against it before allocating.
    pub max_points: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            min_points: 1,
            max_points: 10_000_000,
        }
    }
}

impl PointCloud {
    /// Checks the invariant: at least one point, `min_points..=max_points` points, all finite.
    pub fn validate(&self, limits: &Limits) -> Result<(), PointCloudError> {
        check_count(self.points.len() as u64, limits)?;
        for (index, p) in self.points.iter().enumerate() {
            for (axis, &value) in p.iter().enumerate() {
                if !value.is_finite() {
                    return Err(PointCloudError::NonFinite { index, axis, value });
                }
            }
        }
        Ok(())
    }

    /// Reads a file, choosing the format by its extension (see [`Format::from_path`]).
    pub fn read(path: &Path, limits: &Limits) -> Result<PointCloud, PointCloudError> {
        let format = Format::from_path(path).ok_or_else(|| PointCloudError::UnknownFormat {
            path: path.to_path_buf(),
        })?;
        let bytes = fs::read(path).map_err(|source| PointCloudError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes, format, limits)
    }

    /// Parses `bytes` as `format` (both PLY variants read any PLY encoding) and validates.
    pub fn from_bytes(
        bytes: &[u8],
        format: Format,
        limits: &Limits,
    ) -> Result<PointCloud, PointCloudError> {
        let points = match format {
            Format::Ply | Format::PlyAscii => ply_read(bytes, limits)?,
            Format::Npy => npy_read(bytes, limits)?,
            Format::Json => json_read(bytes, limits)?,
        };
        let cloud = PointCloud { points };
        cloud.validate(limits)?;
        Ok(cloud)
    }

    /// Serialises the cloud. Does not validate: PLY and NPY keep non-finite values as they are,
    /// JSON writes them as `null`; the readers reject both.
    pub fn to_bytes(&self, format: Format) -> Vec<u8> {
        match format {
            Format::Ply => ply_write(&self.points, false),
            Format::PlyAscii => ply_write(&self.points, true),
            Format::Npy => npy_write(&self.points),
            Format::Json => json_write(&self.points),
        }
    }

    /// Atomic write: temp file in the same dir + fsync + rename.
    pub fn write(&self, path: &Path, format: Format) -> Result<(), PointCloudError> {
        atomic_write(path, &self.to_bytes(format))
    }

    /// Axis-aligned bounds (min, max); None if empty. NaN coordinates are ignored.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.points.first()?;
        let mut lo = first;
        let mut hi = first;
        for p in &self.points[1..] {
            for axis in 0..3 {
                lo[axis] = lo[axis].min(p[axis]);
                hi[axis] = hi[axis].max(p[axis]);
            }
        }
        Some((lo, hi))
    }
}

/// Write a coloured PLY (ascii) of points with per-point RGB, for side-by-side visual checks.
/// Atomic like [`PointCloud::write`]; `points` and `colours` must have the same length.
pub fn write_coloured_ply(
    path: &Path,
    points: &[[f32; 3]],
    colours: &[[u8; 3]],
) -> Result<(), PointCloudError> {
    if points.len() != colours.len() {
        return Err(mal(
            PLY,
            format!(
                "coloured PLY needs one colour per point: {} points but {} colours",
                points.len(),
                colours.len()
            ),
        ));
    }
    let mut out = String::with_capacity(200 + points.len() * 40);
    out.push_str("ply\nformat ascii 1.0\ncomment physnap coloured point cloud\n");
    let _ = writeln!(out, "element vertex {}", points.len());
    out.push_str("property float x\nproperty float y\nproperty float z\n");
    out.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n");
    for (p, c) in points.iter().zip(colours) {
        let _ = writeln!(
            out,
            "{:?} {:?} {:?} {} {} {}",
            p[0], p[1], p[2], c[0], c[1], c[2]
        );
    }
    atomic_write(path, out.as_bytes())
}

// ---------------------------------------------------------------------------------------------
// Shared helpers

const PLY: &str = "PLY";
const NPY: &str = "NPY";
const JSON: &str = "JSON";

fn mal(format: &'static str, detail: impl Into<String>) -> PointCloudError {
    PointCloudError::Malformed {
        format,
        detail: detail.into(),
    }
}

fn truncated(format: &'static str, expected_bytes: u64, got_bytes: usize) -> PointCloudError {
    PointCloudError::Truncated {
        format,
        expected_bytes,
        got_bytes: got_bytes as u64,
    }
}

/// Checks a point count (possibly a header's claim) against the limits, before allocating.
fn check_count(count: u64, limits: &Limits) -> Result<usize, PointCloudError> {
    if count > limits.max_points as u64 {
        return Err(PointCloudError::TooMany {
            count,
            max: limits.max_points,
        });
    }
    // count <= max_points, a usize, so this cannot fail; stay panic-free anyway.
    let count = usize::try_from(count).unwrap_or(usize::MAX);
    if count == 0 {
        return Err(PointCloudError::Empty);
    }
    if count < limits.min_points {
        return Err(PointCloudError::TooFew {
            count,
            min: limits.min_points,
        });
    }
    Ok(count)
}

/// At most 40 bytes of untrusted input, escaped, for error messages.
fn snippet(bytes: &[u8]) -> String {
    const MAX: usize = 40;
    let mut s = bytes[..bytes.len().min(MAX)].escape_ascii().to_string();
    if bytes.len() > MAX {
        s.push_str("...");
    }
    s
}

fn atomic_write(path: &Path, bytes: &[u8]) -> Result<(), PointCloudError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let io_err = |p: &Path, source| PointCloudError::Io {
        path: p.to_path_buf(),
        source,
    };
    let Some(file_name) = path.file_name() else {
        return Err(io_err(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name"),
        ));
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let tmp = dir.join(format!(
        ".{}.{}.{}.tmp",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let mut file = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(|e| io_err(&tmp, e))?;
    let written = file.write_all(bytes).and_then(|()| file.sync_all());
    drop(file);
    if let Err(e) = written {
        let _ = fs::remove_file(&tmp);
        return Err(io_err(&tmp, e));
    }
    if let Err(e) = fs::rename(&tmp, path) {
        let _ = fs::remove_file(&tmp);
        return Err(io_err(path, e));
    }
    // Make the rename itself durable (best effort: not every platform can fsync a directory).
    #[cfg(unix)]
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Splits input into lines (`\n`, optional `\r` before it), counting them from 1.
struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    line_no: usize,
}

impl<'a> Lines<'a> {
    fn next_line(&mut self) -> Option<&'a [u8]> {
        let rest = self.bytes.get(self.pos..).filter(|r| !r.is_empty())?;
        let (line, advance) = match rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&rest[..i], i + 1),
            None => (rest, rest.len()),
        };
        self.pos += advance;
        self.line_no += 1;
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    }

    /// Next line with something other than whitespace on it.
    fn next_nonblank(&mut self) -> Option<&'a [u8]> {
        loop {
            let line = self.next_line()?;
            if !line.iter().all(u8::is_ascii_whitespace) {
                return Some(line);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// PLY

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes one value from the start of `b`; None if `b` is too short.
    fn decode(self, b: &[u8], big: bool) -> Option<f32> {
        macro_rules! num {
            ($t:ty, $n:literal) => {{
                let a = *b.first_chunk::<$n>()?;
                if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        Some(match self {
            Scalar::I8 => num!(i8, 1) as f32,
            Scalar::U8 => num!(u8, 1) as f32,
            Scalar::I16 => num!(i16, 2) as f32,
            Scalar::U16 => num!(u16, 2) as f32,
            Scalar::I32 => num!(i32, 4) as f32,
            Scalar::U32 => num!(u32, 4) as f32,
            Scalar::F32 => num!(f32, 4),
            Scalar::F64 => num!(f64, 8) as f32,
        })
    }

    /// Parses an ascii value; None if it is not a number.
    fn parse_ascii(self, tok: &str) -> Option<f32> {
        match self {
            Scalar::F32 => tok.parse::<f32>().ok(),
            _ => tok.parse::<f64>().ok().map(|v| v as f32),
        }
    }
}

#[derive(Debug)]
enum Prop {
    Scalar { name: String, ty: Scalar },
    List { name: String },
}

impl Prop {
    fn name(&self) -> &str {
        match self {
            Prop::Scalar { name, .. } | Prop::List { name, .. } => name,
        }
    }
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Prop>,
    line: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    BinaryLe,
    BinaryBe,
}

fn ply_header<'a>(bytes: &'a [u8]) -> Result<(Encoding, Vec<Element>, Lines<'a>), PointCloudError> {
    let mut lines = Lines {
        bytes,
        pos: 0,
        line_no: 0,
    };
    let first = lines.next_line().unwrap_or(&[]);
    if first.trim_ascii_end() != b"ply" {
        return Err(mal(
            PLY,
            format!(
                "file does not start with the 'ply' magic line (first line is '{}')",
                snippet(first)
            ),
        ));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    // Names seen so far, so that duplicate checks stay linear on hostile headers.
    let mut seen_vertex = false;
    let mut prop_names: HashSet<String> = HashSet::new();
    loop {
        let Some(raw) = lines.next_line() else {
            return Err(mal(
                PLY,
                format!(
                    "header has no 'end_header' line (input ends after line {})",
                    lines.line_no
                ),
            ));
        };
        let n = lines.line_no;
        let text = std::str::from_utf8(raw).map_err(|_| {
            mal(
                PLY,
                format!("header line {n} is not ASCII text: '{}'", snippet(raw)),
            )
        })?;
        let tokens: Vec<&str> = text.split_ascii_whitespace().collect();
        let Some(&keyword) = tokens.first() else {
            continue; // blank header line: tolerated
        };
        let bad_line = |expected: &str| {
            mal(
                PLY,
                format!(
                    "header line {n}: expected '{expected}', got '{}'",
                    snippet(text.as_bytes())
                ),
            )
        };
        match keyword {
            "comment" | "obj_info" => {}
            "end_header" => break,
            "format" => {
                let [_, enc, version] = tokens[..] else {
                    return Err(bad_line("format <encoding> 1.0"));
                };
                if encoding.is_some() {
                    return Err(mal(PLY, format!("header line {n}: second 'format' line")));
                }
                encoding = Some(match enc {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLe,
                    "binary_big_endian" => Encoding::BinaryBe,
                    other => {
                        return Err(mal(
                            PLY,
                            format!(
                                "header line {n}: unknown format '{}' (expected ascii, \
                                 binary_little_endian or binary_big_endian)",
                                snippet(other.as_bytes())
                            ),
                        ));
                    }
                });
                if version != "1.0" && version != "1" {
                    return Err(mal(
                        PLY,
                        format!(
                            "header line {n}: unsupported PLY version '{}' (expected 1.0)",
                            snippet(version.as_bytes())
                        ),
                    ));
                }
            }
            "element" => {
                let [_, name, count] = tokens[..] else {
                    return Err(bad_line("element <name> <count>"));
                };
                let count = count.parse::<u64>().map_err(|_| {
                    let why = if count.parse::<i128>().is_ok_and(|c| c < 0) {
                        "is negative"
                    } else if count.bytes().all(|b| b.is_ascii_digit()) {
                        "is too large"
                    } else {
                        "is not an integer"
                    };
                    mal(
                        PLY,
                        format!(
                            "header line {n}: element {} count '{}' {why}",
                            snippet(name.as_bytes()),
                            snippet(count.as_bytes())
                        ),
                    )
                })?;
                if name == "vertex" && std::mem::replace(&mut seen_vertex, true) {
                    return Err(mal(
                        PLY,
                        format!("header line {n}: second 'vertex' element"),
                    ));
                }
                prop_names.clear();
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                    line: n,
                });
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(mal(
                        PLY,
                        format!("header line {n}: property before any 'element' line"),
                    ));
                };
                let type_err = |ty: &str, name: &str| {
                    mal(
                        PLY,
                        format!(
                            "header line {n}: unknown type '{}' for property '{}' (expected \
                             char, uchar, short, ushort, int, uint, float, double or an \
                             int8..float64 alias)",
                            snippet(ty.as_bytes()),
                            snippet(name.as_bytes())
                        ),
                    )
                };
                let prop = match tokens[..] {
                    [_, "list", count_ty, item_ty, name] => {
                        let count_ty =
                            Scalar::parse(count_ty).ok_or_else(|| type_err(count_ty, name))?;
                        Scalar::parse(item_ty).ok_or_else(|| type_err(item_ty, name))?;
                        if !count_ty.is_integer() {
                            return Err(mal(
                                PLY,
                                format!(
                                    "header line {n}: list property '{}' has a non-integer \
                                     count type",
                                    snippet(name.as_bytes())
                                ),
                            ));
                        }
                        Prop::List {
                            name: name.to_string(),
                        }
                    }
                    [_, ty, name] if ty != "list" => Prop::Scalar {
                        name: name.to_string(),
                        ty: Scalar::parse(ty).ok_or_else(|| type_err(ty, name))?,
                    },
                    _ => {
                        return Err(bad_line(
                            "property <type> <name>' or 'property list <type> <type> <name>",
                        ));
                    }
                };
                if !prop_names.insert(prop.name().to_string()) {
                    return Err(mal(
                        PLY,
                        format!(
                            "header line {n}: element '{}' has a second property '{}'",
                            snippet(element.name.as_bytes()),
                            snippet(prop.name().as_bytes())
                        ),
                    ));
                }
                element.props.push(prop);
            }
            other => {
                return Err(mal(
                    PLY,
                    format!(
                        "header line {n}: unknown keyword '{}' (expected comment, obj_info, \
                         format, element, property or end_header)",
                        snippet(other.as_bytes())
                    ),
                ));
            }
        }
    }
    let Some(encoding) = encoding else {
        return Err(mal(PLY, "header has no 'format' line"));
    };
    Ok((encoding, elements, lines))
}

fn ply_read(bytes: &[u8], limits: &Limits) -> Result<Vec<[f32; 3]>, PointCloudError> {
    let (encoding, elements, mut lines) = ply_header(bytes)?;
    let Some(vi) = elements.iter().position(|e| e.name == "vertex") else {
        return Err(mal(PLY, "header has no 'vertex' element"));
    };
    let vertex = &elements[vi];
    let mut xyz = [0usize; 3]; // index of x, y, z in vertex.props
    for (axis, slot) in xyz.iter_mut().enumerate() {
        let want = axis_name(axis);
        let Some(i) = vertex.props.iter().position(|p| p.name() == want) else {
            let found: Vec<&str> = vertex.props.iter().take(16).map(Prop::name).collect();
            return Err(mal(
                PLY,
                format!(
                    "'vertex' element (header line {}) has no '{want}' property (found: {})",
                    vertex.line,
                    snippet(found.join(", ").as_bytes())
                ),
            ));
        };
        if let Prop::List { .. } = vertex.props[i] {
            return Err(mal(
                PLY,
                format!("'vertex' property '{want}' is a list; expected a scalar type"),
            ));
        }
        *slot = i;
    }
    let count = check_count(vertex.count, limits)?;
    match encoding {
        Encoding::Ascii => ply_read_ascii(&elements[..vi], vertex, xyz, count, &mut lines),
        Encoding::BinaryLe | Encoding::BinaryBe => ply_read_binary(
            &elements[..vi],
            vertex,
            xyz,
            count,
            bytes,
            lines.pos,
            encoding == Encoding::BinaryBe,
        ),
    }
}

fn ply_read_binary(
    before: &[Element],
    vertex: &Element,
    xyz: [usize; 3],
    count: usize,
    bytes: &[u8],
    data_start: usize,
    big: bool,
) -> Result<Vec<[f32; 3]>, PointCloudError> {
    let total = bytes.len();
    let scalar_stride = |el: &Element| -> Result<u64, PointCloudError> {
        let mut stride = 0u64;
        for p in &el.props {
            match p {
                Prop::Scalar { ty, .. } => stride += ty.size() as u64,
                Prop::List { name, .. } => {
                    return Err(mal(
                        PLY,
                        format!(
                            "element '{}' (header line {}) comes before 'vertex' and has list \
                             property '{}'; binary PLY with list properties before the \
                             vertex element is not supported",
                            snippet(el.name.as_bytes()),
                            el.line,
                            snippet(name.as_bytes())
                        ),
                    ));
                }
            }
        }
        Ok(stride)
    };
    // Byte offset (from the start of the input) where each section begins; u64 + saturating
    // so that absurd header claims become a Truncated error, not an overflow.
    let mut offset = data_start as u64;
    for el in before {
        let stride = scalar_stride(el)?;
        offset = offset.saturating_add(el.count.saturating_mul(stride));
        if offset > total as u64 {
            return Err(truncated(PLY, offset, total));
        }
    }
    let mut prop_offsets = Vec::with_capacity(vertex.props.len());
    let mut stride = 0usize;
    for p in &vertex.props {
        match p {
            Prop::Scalar { ty, .. } => {
                prop_offsets.push(stride);
                stride += ty.size();
            }
            Prop::List { name, .. } => {
                return Err(mal(
                    PLY,
                    format!(
                        "'vertex' element has list property '{}'; binary PLY vertices with \
                         list properties are not supported",
                        snippet(name.as_bytes())
                    ),
                ));
            }
        }
    }
    let end = offset.saturating_add((count as u64).saturating_mul(stride as u64));
    if end > total as u64 {
        return Err(truncated(PLY, end, total));
    }
    // offset <= end <= total, so both fit a usize.
    let data = &bytes[offset as usize..end as usize];
    let mut fields = [(0usize, Scalar::F32); 3];
    for (field, &pi) in fields.iter_mut().zip(&xyz) {
        if let Prop::Scalar { ty, .. } = vertex.props[pi] {
            *field = (prop_offsets[pi], ty);
        }
    }
    let mut points = Vec::with_capacity(count);
    for record in data.chunks_exact(stride) {
        let mut p = [0f32; 3];
        for (v, &(off, ty)) in p.iter_mut().zip(&fields) {
            *v = record
                .get(off..)
                .and_then(|b| ty.decode(b, big))
                .ok_or_else(|| truncated(PLY, end, total))?;
        }
        points.push(p);
    }
    Ok(points)
}

fn ply_read_ascii(
    before: &[Element],
    vertex: &Element,
    xyz: [usize; 3],
    count: usize,
    lines: &mut Lines<'_>,
) -> Result<Vec<[f32; 3]>, PointCloudError> {
    let ended = |done: u64, el: &Element, line_no: usize| {
        mal(
            PLY,
            format!(
                "data ends after {done} of {} '{}' lines (line {line_no})",
                el.count,
                snippet(el.name.as_bytes())
            ),
        )
    };
    for el in before {
        for done in 0..el.count {
            if lines.next_nonblank().is_none() {
                return Err(ended(done, el, lines.line_no));
            }
        }
    }
    let has_list = vertex.props.iter().any(|p| matches!(p, Prop::List { .. }));
    // Each value takes at least two bytes (digit + separator): never reserve more than the
    // remaining input could hold, whatever the header claims.
    let remaining = lines.bytes.len().saturating_sub(lines.pos);
    let mut points = Vec::with_capacity(count.min(remaining / (2 * vertex.props.len()) + 1));
    let mut tokens: Vec<&str> = Vec::with_capacity(vertex.props.len());
    for i in 0..count {
        let Some(raw) = lines.next_nonblank() else {
            return Err(ended(i as u64, vertex, lines.line_no));
        };
        let ln = lines.line_no;
        let text = std::str::from_utf8(raw).map_err(|_| {
            mal(
                PLY,
                format!("line {ln} is not ASCII text: '{}'", snippet(raw)),
            )
        })?;
        tokens.clear();
        tokens.extend(text.split_ascii_whitespace());
        if !has_list && tokens.len() != vertex.props.len() {
            return Err(mal(
                PLY,
                format!(
                    "line {ln}: vertex {i} has {} values, expected {}",
                    tokens.len(),
                    vertex.props.len()
                ),
            ));
        }
        let too_few = || {
            mal(
                PLY,
                format!(
                    "line {ln}: vertex {i} has {} values, too few for its properties",
                    tokens.len()
                ),
            )
        };
        let not_number = |name: &str, tok: &str| {
            mal(
                PLY,
                format!(
                    "line {ln}: vertex {i} property '{}' value '{}' is not a number",
                    snippet(name.as_bytes()),
                    snippet(tok.as_bytes())
                ),
            )
        };
        let mut t = 0usize;
        let mut p = [0f32; 3];
        for (pi, prop) in vertex.props.iter().enumerate() {
            match prop {
                Prop::Scalar { name, ty } => {
                    let tok = *tokens.get(t).ok_or_else(too_few)?;
                    t += 1;
                    let v = ty.parse_ascii(tok).ok_or_else(|| not_number(name, tok))?;
                    if let Some(axis) = xyz.iter().position(|&k| k == pi) {
                        p[axis] = v;
                    }
                }
                Prop::List { name, .. } => {
                    let tok = *tokens.get(t).ok_or_else(too_few)?;
                    t += 1;
                    let n = tok.parse::<usize>().map_err(|_| {
                        mal(
                            PLY,
                            format!(
                                "line {ln}: vertex {i} list property '{}' count '{}' is not a \
                                 non-negative integer",
                                snippet(name.as_bytes()),
                                snippet(tok.as_bytes())
                            ),
                        )
                    })?;
                    let items = tokens
                        .get(t..)
                        .and_then(|r| r.get(..n))
                        .ok_or_else(too_few)?;
                    if let Some(bad) = items.iter().find(|s| s.parse::<f64>().is_err()) {
                        return Err(not_number(name, bad));
                    }
                    t += n;
                }
            }
        }
        if t != tokens.len() {
            return Err(mal(
                PLY,
                format!(
                    "line {ln}: vertex {i} has {} values, expected {t}",
                    tokens.len()
                ),
            ));
        }
        points.push(p);
    }
    Ok(points)
}

fn ply_write(points: &[[f32; 3]], ascii: bool) -> Vec<u8> {
    let encoding = if ascii {
        "ascii"
    } else {
        "binary_little_endian"
    };
    let header = format!(
        "ply\nformat {encoding} 1.0\ncomment physnap point cloud (object frame, metres)\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        points.len()
    );
    if ascii {
        let mut out = String::with_capacity(header.len() + points.len() * 36);
        out.push_str(&header);
        for p in points {
            let _ = writeln!(out, "{:?} {:?} {:?}", p[0], p[1], p[2]);
        }
        out.into_bytes()
    } else {
        let mut out = Vec::with_capacity(header.len() + points.len() * 12);
        out.extend_from_slice(header.as_bytes());
        for p in points {
            for v in p {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }
}

// ---------------------------------------------------------------------------------------------
// NPY

const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// A Python literal as found in an NPY header.
#[derive(Debug, PartialEq)]
enum Py {
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

/// Recursive-descent parser for the Python literal subset numpy writes in NPY headers.
struct PyParser<'a> {
    s: &'a [u8],
    pos: usize,
}

impl PyParser<'_> {
    const MAX_DEPTH: usize = 16;

    fn skip_ws(&mut self) {
        while self.s.get(self.pos).is_some_and(u8::is_ascii_whitespace) {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip_ws();
        self.s.get(self.pos).copied()
    }

    fn unexpected(&self) -> String {
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

    fn value(&mut self, depth: usize) -> Result<Py, String> {
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

    fn string(&mut self, quote: u8) -> Result<Py, String> {
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

    fn int(&mut self) -> Result<Py, String> {
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

    fn seq(&mut self, close: u8, depth: usize) -> Result<Vec<Py>, String> {
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

    fn dict(&mut self, depth: usize) -> Result<Py, String> {
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

fn npy_read(bytes: &[u8], limits: &Limits) -> Result<Vec<[f32; 3]>, PointCloudError> {
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

fn npy_write(points: &[[f32; 3]]) -> Vec<u8> {
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

// ---------------------------------------------------------------------------------------------
// JSON

fn json_kind(v: &serde_json::Value) -> String {
    use serde_json::Value;
    match v {
        Value::Null => "null".to_string(),
        Value::Bool(b) => format!("a boolean ({b})"),
        Value::Number(n) => format!("a number ({n})"),
        Value::String(s) => format!("a string (\"{}\")", snippet(s.as_bytes())),
        Value::Array(a) => format!("an array of {} values", a.len()),
        Value::Object(_) => "an object".to_string(),
    }
}

fn json_read(bytes: &[u8], limits: &Limits) -> Result<Vec<[f32; 3]>, PointCloudError> {
    use serde_json::Value;
    let value: Value =
        serde_json::from_slice(bytes).map_err(|e| mal(JSON, format!("not valid JSON: {e}")))?;
    let expected = "an array of [x, y, z] arrays or an object with a 'points' array";
    let list = match &value {
        Value::Array(list) => list,
        Value::Object(map) => match map.get("points") {
            Some(Value::Array(list)) => list,
            Some(other) => {
                return Err(mal(
                    JSON,
                    format!(
                        "'points' is {}; expected an array of [x, y, z] arrays",
                        json_kind(other)
                    ),
                ));
            }
            None => {
                let keys: Vec<&str> = map.keys().take(8).map(String::as_str).collect();
                return Err(mal(
                    JSON,
                    format!(
                        "object has no 'points' key (keys: {}); expected {expected}",
                        snippet(keys.join(", ").as_bytes())
                    ),
                ));
            }
        },
        other => {
            return Err(mal(
                JSON,
                format!(
                    "top-level value is {}; expected {expected}",
                    json_kind(other)
                ),
            ));
        }
    };
    let count = check_count(list.len() as u64, limits)?;
    let mut points = Vec::with_capacity(count);
    for (i, item) in list.iter().enumerate() {
        let Value::Array(coords) = item else {
            let hint = if item.is_number() {
                " (flat arrays of numbers are not accepted; group them as [[x, y, z], ...])"
            } else {
                ""
            };
            return Err(mal(
                JSON,
                format!(
                    "points[{i}] is {}, expected an [x, y, z] array{hint}",
                    json_kind(item)
                ),
            ));
        };
        if coords.len() != 3 {
            return Err(mal(
                JSON,
                format!("points[{i}] has {} values, expected 3", coords.len()),
            ));
        }
        let mut p = [0f32; 3];
        for (axis, (v, c)) in p.iter_mut().zip(coords).enumerate() {
            let Some(x) = c.as_f64() else {
                return Err(mal(
                    JSON,
                    format!("points[{i}][{axis}] is {}, expected a number", json_kind(c)),
                ));
            };
            // Out of f32 range becomes ±inf here, which validate reports as NonFinite.
            *v = x as f32;
        }
        points.push(p);
    }
    Ok(points)
}

/// Appends `v` as a JSON number that reads back (as f64, then cast to f32) to exactly `v`:
/// the short f32 form when that round-trips, else the exact f64 form. Non-finite → `null`.
fn json_number(out: &mut String, v: f32) {
    if !v.is_finite() {
        out.push_str("null");
        return;
    }
    let start = out.len();
    let _ = write!(out, "{v:?}");
    let exact = out[start..]
        .parse::<f64>()
        .is_ok_and(|back| (back as f32).to_bits() == v.to_bits());
    if !exact {
        out.truncate(start);
        let _ = write!(out, "{:?}", f64::from(v));
    }
}

fn json_write(points: &[[f32; 3]]) -> Vec<u8> {
    let mut out = String::with_capacity(16 + points.len() * 40);
    out.push_str("{\"points\":[");
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push('[');
        for (axis, &v) in p.iter().enumerate() {
            if axis > 0 {
                out.push(',');
            }
            json_number(&mut out, v);
        }
        out.push(']');
    }
    out.push_str("]}");
    out.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::time::{Duration, Instant};

    const ALL: [Format; 4] = [Format::Ply, Format::PlyAscii, Format::Npy, Format::Json];

    fn sample() -> PointCloud {
        PointCloud {
            points: vec![
                [0.0, 0.0, 0.0],
                [0.1, -0.2, 0.3],
                [1.5e-7, -3.25e5, 12.0],
                [-0.0, 1.0 / 3.0, f32::MAX],
                [f32::MIN_POSITIVE, -f32::MIN_POSITIVE / 4.0, 1e-45],
            ],
        }
    }

    fn bits(points: &[[f32; 3]]) -> Vec<[u32; 3]> {
        points.iter().map(|p| p.map(f32::to_bits)).collect()
    }

    /// Asserts the error kind and that the message contains every needle.
    #[track_caller]
    fn expect_err(res: Result<PointCloud, PointCloudError>, kind: &str, needles: &[&str]) {
        let err = match res {
            Ok(c) => panic!(
                "expected a {kind} error, got Ok with {} points",
                c.points.len()
            ),
            Err(e) => e,
        };
        let msg = err.to_string();
        assert_eq!(err.error_type(), kind, "wrong kind for: {msg}");
        for needle in needles {
            assert!(msg.contains(needle), "message {msg:?} lacks {needle:?}");
        }
    }

    fn read(bytes: &[u8], format: Format) -> Result<PointCloud, PointCloudError> {
        PointCloud::from_bytes(bytes, format, &Limits::default())
    }

    fn binary_ply(encoding: &str, props: &str, count: u64, body: &[u8]) -> Vec<u8> {
        let mut out =
            format!("ply\nformat {encoding} 1.0\nelement vertex {count}\n{props}end_header\n")
                .into_bytes();
        out.extend_from_slice(body);
        out
    }

    const XYZ_FLOAT: &str = "property float x\nproperty float y\nproperty float z\n";

    fn le_f32s(values: &[f32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    fn npy(descr: &str, fortran: bool, shape: &str, body: &[u8]) -> Vec<u8> {
        let fo = if fortran { "True" } else { "False" };
        let header = format!("{{'descr': '{descr}', 'fortran_order': {fo}, 'shape': {shape}, }}\n");
        let mut out = NPY_MAGIC.to_vec();
        out.extend_from_slice(&[1, 0]);
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(body);
        out
    }

    #[test]
    fn round_trip_every_format_bit_exact() {
        let cloud = sample();
        for format in ALL {
            let bytes = cloud.to_bytes(format);
            let back = read(&bytes, format).unwrap_or_else(|e| panic!("{format:?}: {e}"));
            assert_eq!(bits(&back.points), bits(&cloud.points), "{format:?}");
        }
    }

    #[test]
    fn file_round_trip_is_atomic_and_leaves_no_temp_file() {
        let dir = tempfile::tempdir().unwrap();
        let cloud = sample();
        for (name, format) in [
            ("a.ply", Format::Ply),
            ("b.PLY", Format::PlyAscii),
            ("c.npy", Format::Npy),
            ("d.Json", Format::Json),
        ] {
            let path = dir.path().join(name);
            cloud.write(&path, format).unwrap();
            // Overwriting goes through the same temp + rename path.
            cloud.write(&path, format).unwrap();
            let back = PointCloud::read(&path, &Limits::default()).unwrap();
            assert_eq!(back, cloud, "{name}");
        }
        let mut names: Vec<String> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["a.ply", "b.PLY", "c.npy", "d.Json"]);
    }

    #[test]
    fn write_into_missing_directory_is_io_error_naming_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing").join("x.ply");
        let err = sample().write(&path, Format::Ply).unwrap_err();
        assert_eq!(err.error_type(), "io");
        assert!(err.to_string().contains("missing"), "{err}");
    }

    #[test]
    fn read_errors_for_unknown_extension_and_missing_file() {
        let err = PointCloud::read(Path::new("cloud.xyz"), &Limits::default()).unwrap_err();
        assert_eq!(err.error_type(), "unknown_format");
        assert!(err.to_string().contains("cloud.xyz"), "{err}");
        let err =
            PointCloud::read(Path::new("/nonexistent/c.ply"), &Limits::default()).unwrap_err();
        assert_eq!(err.error_type(), "io");
        assert!(err.to_string().contains("/nonexistent/c.ply"), "{err}");
    }

    #[test]
    fn format_from_path() {
        assert_eq!(Format::from_path(Path::new("a/b.ply")), Some(Format::Ply));
        assert_eq!(Format::from_path(Path::new("b.PlY")), Some(Format::Ply));
        assert_eq!(Format::from_path(Path::new("b.NPY")), Some(Format::Npy));
        assert_eq!(Format::from_path(Path::new("b.json")), Some(Format::Json));
        assert_eq!(Format::from_path(Path::new("b.txt")), None);
        assert_eq!(Format::from_path(Path::new("ply")), None);
    }

    #[test]
    fn npy_f64_big_endian_fortran_and_v2() {
        let pts = [[1.0f64, 2.0, 3.0], [-4.5, 5.25, 1e-3]];
        let expect: Vec<[f32; 3]> = pts.iter().map(|p| p.map(|v| v as f32)).collect();
        let le8: Vec<u8> = pts.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let c = read(&npy("<f8", false, "(2, 3)", &le8), Format::Npy).unwrap();
        assert_eq!(c.points, expect);
        let be8: Vec<u8> = pts.iter().flatten().flat_map(|v| v.to_be_bytes()).collect();
        let c = read(&npy(">f8", false, "(2, 3)", &be8), Format::Npy).unwrap();
        assert_eq!(c.points, expect);
        let be4: Vec<u8> = expect
            .iter()
            .flatten()
            .flat_map(|v| v.to_be_bytes())
            .collect();
        let c = read(&npy(">f4", false, "(2, 3)", &be4), Format::Npy).unwrap();
        assert_eq!(c.points, expect);
        // Fortran order: all x, then all y, then all z.
        let cols: Vec<f32> = (0..3)
            .flat_map(|a| expect.iter().map(move |p| p[a]))
            .collect();
        let c = read(&npy("<f4", true, "(2, 3)", &le_f32s(&cols)), Format::Npy).unwrap();
        assert_eq!(c.points, expect);
        // Version 2.0: 4-byte header length, double quotes, Python 2 long ints.
        let header = "{\"descr\": \"<f4\", \"fortran_order\": False, \"shape\": (2L, 3L)}\n";
        let mut v2 = NPY_MAGIC.to_vec();
        v2.extend_from_slice(&[2, 0]);
        v2.extend_from_slice(&(header.len() as u32).to_le_bytes());
        v2.extend_from_slice(header.as_bytes());
        v2.extend_from_slice(&le_f32s(expect.as_flattened()));
        assert_eq!(read(&v2, Format::Npy).unwrap().points, expect);
    }

    #[test]
    fn npy_written_layout_matches_numpy() {
        let bytes = sample().to_bytes(Format::Npy);
        assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
        let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        let data_start = 10 + header_len;
        assert_eq!(data_start % 64, 0);
        assert_eq!(bytes[data_start - 1], b'\n');
        let header = std::str::from_utf8(&bytes[10..data_start]).unwrap();
        assert!(header.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (5, 3), }"));
        assert_eq!(bytes.len(), data_start + 5 * 12);
    }

    #[test]
    fn big_endian_binary_ply_with_mixed_types() {
        // x double, an int we skip, y float, z short (integers are converted).
        let props = "property double x\nproperty int id\nproperty float y\nproperty short z\n";
        let mut body = Vec::new();
        for (x, id, y, z) in [(1.5f64, 7i32, -2.25f32, 3i16), (-0.5, 8, 4.0, -9)] {
            body.extend_from_slice(&x.to_be_bytes());
            body.extend_from_slice(&id.to_be_bytes());
            body.extend_from_slice(&y.to_be_bytes());
            body.extend_from_slice(&z.to_be_bytes());
        }
        let c = read(
            &binary_ply("binary_big_endian", props, 2, &body),
            Format::Ply,
        )
        .unwrap();
        assert_eq!(c.points, vec![[1.5, -2.25, 3.0], [-0.5, 4.0, -9.0]]);
    }

    #[test]
    fn ascii_ply_with_extra_properties_and_faces_after_vertices() {
        let text = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info scanner 3\r\n\
            element vertex 3\r\nproperty float32 x\r\nproperty float32 y\r\nproperty float32 z\r\n\
            property float nx\r\nproperty float ny\r\nproperty float nz\r\n\
            property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n\
            element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n\
            0 0 0 0 0 1 255 0 0\r\n1 0 0 0 0 1 0 255 0\r\n\r\n0 1 0.5 0 0 1 0 0 255\r\n\
            3 0 1 2\r\n";
        let c = read(text.as_bytes(), Format::PlyAscii).unwrap();
        assert_eq!(
            c.points,
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]
        );
    }

    #[test]
    fn binary_ply_with_face_after_vertices() {
        let props = format!("{XYZ_FLOAT}element face 1\nproperty list uchar int vertex_indices\n");
        let mut body = le_f32s(&[1.0, 2.0, 3.0]);
        body.extend_from_slice(&[3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]);
        let c = read(
            &binary_ply("binary_little_endian", &props, 1, &body),
            Format::Ply,
        )
        .unwrap();
        assert_eq!(c.points, vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn ply_properties_in_order_z_y_x() {
        let props = "property float z\nproperty float y\nproperty float x\n";
        let body = le_f32s(&[3.0, 2.0, 1.0, 6.0, 5.0, 4.0]);
        let c = read(
            &binary_ply("binary_little_endian", props, 2, &body),
            Format::Ply,
        )
        .unwrap();
        assert_eq!(c.points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        let text = format!("ply\nformat ascii 1.0\nelement vertex 1\n{props}end_header\n3 2 1\n");
        let c = read(text.as_bytes(), Format::Ply).unwrap();
        assert_eq!(c.points, vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn elements_before_vertex() {
        // Binary: a scalar-only element before vertex is skipped by size.
        let text = format!(
            "ply\nformat binary_little_endian 1.0\nelement camera 2\nproperty double fx\n\
             property uchar flag\nelement vertex 1\n{XYZ_FLOAT}end_header\n"
        );
        let mut bytes = text.into_bytes();
        bytes.extend_from_slice(&[0xAB; 18]);
        bytes.extend_from_slice(&le_f32s(&[7.0, 8.0, 9.0]));
        assert_eq!(
            read(&bytes, Format::Ply).unwrap().points,
            vec![[7.0, 8.0, 9.0]]
        );
        // Binary with a list property before vertex: clear error naming element and property.
        let text = format!(
            "ply\nformat binary_little_endian 1.0\nelement face 1\n\
             property list uchar int vertex_indices\nelement vertex 1\n{XYZ_FLOAT}end_header\n"
        );
        expect_err(
            read(text.as_bytes(), Format::Ply),
            "malformed",
            &["'face'", "'vertex_indices'", "before 'vertex'"],
        );
        // Ascii: any element before vertex is skipped line by line.
        let text = format!(
            "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
             element vertex 1\n{XYZ_FLOAT}end_header\n3 0 1 2\n7 8 9\n"
        );
        assert_eq!(
            read(text.as_bytes(), Format::Ply).unwrap().points,
            vec![[7.0, 8.0, 9.0]]
        );
    }

    #[test]
    fn ply_header_errors_name_the_problem() {
        expect_err(
            read(b"plx\nformat ascii 1.0\n", Format::Ply),
            "malformed",
            &["'ply' magic", "plx"],
        );
        expect_err(read(b"", Format::Ply), "malformed", &["'ply' magic"]);
        let unknown = format!(
            "ply\nformat binary_middle_endian 1.0\nelement vertex 1\n{XYZ_FLOAT}end_header\n"
        );
        expect_err(
            read(unknown.as_bytes(), Format::Ply),
            "malformed",
            &["header line 2", "unknown format 'binary_middle_endian'"],
        );
        let no_end = format!("ply\nformat ascii 1.0\nelement vertex 1\n{XYZ_FLOAT}0 0 0\n");
        expect_err(
            read(no_end.as_bytes(), Format::Ply),
            "malformed",
            &["header line 7", "unknown keyword '0'", "end_header"],
        );
        let header_only = format!("ply\nformat ascii 1.0\nelement vertex 1\n{XYZ_FLOAT}");
        expect_err(
            read(header_only.as_bytes(), Format::Ply),
            "malformed",
            &["no 'end_header' line", "after line 6"],
        );
        let no_y = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float z\nend_header\n0 0\n";
        expect_err(
            read(no_y.as_bytes(), Format::Ply),
            "malformed",
            &["no 'y' property", "found: x, z"],
        );
        let bad_count =
            format!("ply\nformat ascii 1.0\nelement vertex abc\n{XYZ_FLOAT}end_header\n");
        expect_err(
            read(bad_count.as_bytes(), Format::Ply),
            "malformed",
            &[
                "header line 3",
                "element vertex count 'abc' is not an integer",
            ],
        );
        let neg_count =
            format!("ply\nformat ascii 1.0\nelement vertex -4\n{XYZ_FLOAT}end_header\n");
        expect_err(
            read(neg_count.as_bytes(), Format::Ply),
            "malformed",
            &["'-4' is negative"],
        );
        let bad_type = "ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n";
        expect_err(
            read(bad_type.as_bytes(), Format::Ply),
            "malformed",
            &["header line 4", "'half'", "'x'"],
        );
        let no_vertex = "ply\nformat ascii 1.0\nelement face 0\nend_header\n";
        expect_err(
            read(no_vertex.as_bytes(), Format::Ply),
            "malformed",
            &["no 'vertex' element"],
        );
        let no_format = format!("ply\nelement vertex 1\n{XYZ_FLOAT}end_header\n0 0 0\n");
        expect_err(
            read(no_format.as_bytes(), Format::Ply),
            "malformed",
            &["no 'format' line"],
        );
        let keyword = "ply\nformat ascii 1.0\nfrobnicate 3\nend_header\n";
        expect_err(
            read(keyword.as_bytes(), Format::Ply),
            "malformed",
            &["header line 3", "'frobnicate'"],
        );
    }

    #[test]
    fn ply_ascii_data_errors_name_the_line() {
        let head = format!("ply\nformat ascii 1.0\nelement vertex 2\n{XYZ_FLOAT}end_header\n");
        let short = format!("{head}0 0 0\n1 2\n");
        expect_err(
            read(short.as_bytes(), Format::Ply),
            "malformed",
            &["line 9", "vertex 1 has 2 values, expected 3"],
        );
        let word = format!("{head}0 0 0\n1 two 3\n");
        expect_err(
            read(word.as_bytes(), Format::Ply),
            "malformed",
            &["line 9", "property 'y' value 'two' is not a number"],
        );
        let ended = format!("{head}0 0 0\n");
        expect_err(
            read(ended.as_bytes(), Format::Ply),
            "malformed",
            &["after 1 of 2 'vertex' lines"],
        );
        let nan = format!("{head}0 0 0\n1 2 nan\n");
        expect_err(
            read(nan.as_bytes(), Format::Ply),
            "non_finite",
            &["point 1", "z coordinate", "NaN"],
        );
    }

    #[test]
    fn truncated_binary_ply_reports_expected_and_got_bytes() {
        let body = le_f32s(&[1.0, 2.0, 3.0, 4.0, 5.0]); // 20 of 24 bytes
        let bytes = binary_ply("binary_little_endian", XYZ_FLOAT, 2, &body);
        let header_len = bytes.len() - 20;
        let need = (header_len + 24).to_string();
        let got = bytes.len().to_string();
        expect_err(
            read(&bytes, Format::Ply),
            "truncated",
            &["PLY", &need, &got],
        );
    }

    #[test]
    fn non_finite_points_name_index_and_axis() {
        let body = le_f32s(&[0.0, 0.0, 0.0, 1.0, f32::NAN, 2.0]);
        let bytes = binary_ply("binary_little_endian", XYZ_FLOAT, 2, &body);
        expect_err(
            read(&bytes, Format::Ply),
            "non_finite",
            &["point 1 has a non-finite y coordinate (NaN)"],
        );
        let npy_bytes = npy(
            "<f4",
            false,
            "(2, 3)",
            &le_f32s(&[0.0, 0.0, 0.0, 1.0, 1.0, f32::NAN]),
        );
        expect_err(
            read(&npy_bytes, Format::Npy),
            "non_finite",
            &["point 1 has a non-finite z coordinate (NaN)"],
        );
        let body = le_f32s(&[f32::INFINITY, 0.0, 0.0]);
        let bytes = binary_ply("binary_little_endian", XYZ_FLOAT, 1, &body);
        expect_err(
            read(&bytes, Format::Ply),
            "non_finite",
            &["point 0 has a non-finite x coordinate (inf)"],
        );
        let cloud = PointCloud {
            points: vec![[0.0; 3], [0.0; 3], [f32::NEG_INFINITY, 0.0, 0.0]],
        };
        for format in [Format::Ply, Format::PlyAscii, Format::Npy] {
            expect_err(
                read(&cloud.to_bytes(format), format),
                "non_finite",
                &["point 2", "x coordinate", "-inf"],
            );
        }
        // JSON cannot hold inf: it is written as null and rejected by the reader.
        expect_err(
            read(&cloud.to_bytes(Format::Json), Format::Json),
            "malformed",
            &["points[2][0] is null"],
        );
        // Out of f32 range in JSON.
        expect_err(
            read(br#"[[0, 0, 0], [0, 1e39, 0]]"#, Format::Json),
            "non_finite",
            &["point 1 has a non-finite y coordinate (inf)"],
        );
    }

    #[test]
    fn empty_and_limits() {
        let empty_ply = binary_ply("binary_little_endian", XYZ_FLOAT, 0, &[]);
        expect_err(read(&empty_ply, Format::Ply), "empty", &["0 points"]);
        expect_err(
            read(&npy("<f4", false, "(0, 3)", &[]), Format::Npy),
            "empty",
            &["empty"],
        );
        expect_err(read(b"{\"points\": []}", Format::Json), "empty", &["empty"]);
        expect_err(
            PointCloud::default()
                .validate(&Limits::default())
                .map(|()| PointCloud::default()),
            "empty",
            &[],
        );
        let limits = Limits {
            min_points: 10,
            max_points: 3,
        };
        let few = PointCloud {
            points: vec![[0.0; 3]; 2],
        };
        let err = few.validate(&limits).unwrap_err();
        assert_eq!(err.error_type(), "too_few");
        assert_eq!(err.to_string(), "too few points: 2 (minimum 10)");
        let limits = Limits {
            min_points: 1,
            max_points: 3,
        };
        let many = PointCloud {
            points: vec![[0.0; 3]; 4],
        };
        let err = many.validate(&limits).unwrap_err();
        assert_eq!(err.error_type(), "too_many");
        assert_eq!(err.to_string(), "too many points: 4 (limit 3)");
        for format in ALL {
            let res = PointCloud::from_bytes(&many.to_bytes(format), format, &limits);
            expect_err(res, "too_many", &["4", "limit 3"]);
        }
    }

    #[test]
    fn huge_claimed_counts_fail_fast_without_allocating() {
        let start = Instant::now();
        let claim: u64 = 1_000_000_000_000;
        let body = le_f32s(&[1.0, 2.0, 3.0]);
        for enc in ["binary_little_endian", "binary_big_endian", "ascii"] {
            let bytes = binary_ply(enc, XYZ_FLOAT, claim, &body);
            expect_err(
                read(&bytes, Format::Ply),
                "too_many",
                &["1000000000000", "limit 10000000"],
            );
        }
        let npy_bytes = npy("<f4", false, "(1000000000000, 3)", &body);
        expect_err(
            read(&npy_bytes, Format::Npy),
            "too_many",
            &["1000000000000"],
        );
        // With no limit at all the readers must still not trust the header.
        let open = Limits {
            min_points: 1,
            max_points: usize::MAX,
        };
        let bytes = binary_ply("binary_little_endian", XYZ_FLOAT, claim, &body);
        let res = PointCloud::from_bytes(&bytes, Format::Ply, &open);
        expect_err(res, "truncated", &["12000000000", &bytes.len().to_string()]);
        let bytes = binary_ply("ascii", XYZ_FLOAT, claim, b"1 2 3\n");
        let res = PointCloud::from_bytes(&bytes, Format::Ply, &open);
        expect_err(
            res,
            "malformed",
            &["after 1 of 1000000000000 'vertex' lines"],
        );
        let res = PointCloud::from_bytes(&npy_bytes, Format::Npy, &open);
        expect_err(res, "truncated", &["12000000000"]);
        let before = format!(
            "ply\nformat binary_little_endian 1.0\nelement junk 18446744073709551615\n\
             property double a\nelement vertex 1\n{XYZ_FLOAT}end_header\n"
        );
        let res = PointCloud::from_bytes(before.as_bytes(), Format::Ply, &open);
        expect_err(res, "truncated", &[]);
        assert!(
            start.elapsed() < Duration::from_secs(2),
            "took {:?}",
            start.elapsed()
        );
    }

    #[test]
    fn hostile_headers_stay_linear() {
        // 200k properties / elements: a quadratic duplicate check would take minutes.
        let mut h = String::from("ply\nformat binary_little_endian 1.0\nelement vertex 1\n");
        for i in 0..200_000 {
            let _ = writeln!(h, "property uchar p{i}");
        }
        h.push_str(XYZ_FLOAT);
        for i in 0..100_000 {
            let _ = writeln!(h, "element e{i} 5");
        }
        h.push_str("end_header\n");
        let start = Instant::now();
        let res = read(h.as_bytes(), Format::Ply);
        expect_err(res, "truncated", &[]);
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "took {:?}",
            start.elapsed()
        );
        let dup = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\nend_header\n";
        expect_err(
            read(dup.as_bytes(), Format::Ply),
            "malformed",
            &["header line 5", "second property 'x'"],
        );
        let two = format!(
            "ply\nformat ascii 1.0\nelement vertex 1\n{XYZ_FLOAT}element vertex 1\nend_header\n"
        );
        expect_err(
            read(two.as_bytes(), Format::Ply),
            "malformed",
            &["header line 7", "second 'vertex'"],
        );
    }

    #[test]
    fn npy_errors_name_the_problem() {
        let body = le_f32s(&[1.0, 2.0, 3.0, 4.0, 5.0]);
        let bytes = npy("<f4", false, "(2, 3)", &body);
        let need = (bytes.len() - 20 + 24).to_string();
        expect_err(
            read(&bytes, Format::Npy),
            "truncated",
            &["NPY", &need, &bytes.len().to_string()],
        );
        expect_err(
            read(&npy("<i4", false, "(2, 3)", &body), Format::Npy),
            "malformed",
            &["'descr' is '<i4'"],
        );
        expect_err(
            read(&npy("<f4", false, "(3, 2)", &body), Format::Npy),
            "malformed",
            &["'shape' is (3, 2)", "expected (N, 3)"],
        );
        expect_err(
            read(&npy("<f4", false, "(3,)", &body), Format::Npy),
            "malformed",
            &["'shape' is (3,)"],
        );
        expect_err(
            read(&npy("<f4", false, "(1, 3, 1)", &body), Format::Npy),
            "malformed",
            &["(1, 3, 1)"],
        );
        expect_err(
            read(b"\x93NUMPX\x01\x00", Format::Npy),
            "malformed",
            &["magic", "NUMPX"],
        );
        expect_err(
            read(b"\x93NUMPY\x04\x00\x10\x00", Format::Npy),
            "malformed",
            &["version 4.0"],
        );
        expect_err(
            read(b"\x93NUMPY\x01\x00\xff\x00{", Format::Npy),
            "truncated",
            &["265", "11"],
        );
        let mut no_shape = NPY_MAGIC.to_vec();
        let header = "{'descr': '<f4', 'fortran_order': False}";
        no_shape.extend_from_slice(&[1, 0, header.len() as u8, 0]);
        no_shape.extend_from_slice(header.as_bytes());
        expect_err(
            read(&no_shape, Format::Npy),
            "malformed",
            &["no 'shape' key"],
        );
        let mut garbage = NPY_MAGIC.to_vec();
        garbage.extend_from_slice(&[1, 0, 12, 0]);
        garbage.extend_from_slice(b"{'descr': @}");
        expect_err(
            read(&garbage, Format::Npy),
            "malformed",
            &["header dict", "'@'"],
        );
    }

    #[test]
    fn json_shapes_and_errors() {
        let bare = read(b"[[1, 2, 3], [4.5, -5, 6e-3]]", Format::Json).unwrap();
        assert_eq!(bare.points, vec![[1.0, 2.0, 3.0], [4.5, -5.0, 6e-3]]);
        let obj = read(br#"{"units": "m", "points": [[1, 2, 3]]}"#, Format::Json).unwrap();
        assert_eq!(obj.points, vec![[1.0, 2.0, 3.0]]);
        let mut twelve = vec!["[0,0,0]"; 12];
        twelve.push("[1,2]");
        let text = format!("{{\"points\": [{}]}}", twelve.join(","));
        expect_err(
            read(text.as_bytes(), Format::Json),
            "malformed",
            &["points[12] has 2 values, expected 3"],
        );
        expect_err(
            read(br#""hello""#, Format::Json),
            "malformed",
            &["top-level value is a string", "hello"],
        );
        expect_err(
            read(b"[1, 2, 3]", Format::Json),
            "malformed",
            &["points[0] is a number (1)", "flat"],
        );
        expect_err(
            read(br#"{"pts": []}"#, Format::Json),
            "malformed",
            &["no 'points' key", "pts"],
        );
        expect_err(
            read(br#"{"points": 3}"#, Format::Json),
            "malformed",
            &["'points' is a number (3)"],
        );
        expect_err(
            read(br#"[[1, "2", 3]]"#, Format::Json),
            "malformed",
            &["points[0][1] is a string"],
        );
        expect_err(
            read(b"[[1, 2, 3]", Format::Json),
            "malformed",
            &["not valid JSON", "line 1"],
        );
        let deep = "[".repeat(100_000);
        expect_err(
            read(deep.as_bytes(), Format::Json),
            "malformed",
            &["not valid JSON"],
        );
    }

    #[test]
    fn json_written_compact_and_short() {
        let c = PointCloud {
            points: vec![[0.1, -2.0, 1e-7]],
        };
        assert_eq!(
            String::from_utf8(c.to_bytes(Format::Json)).unwrap(),
            r#"{"points":[[0.1,-2.0,1e-7]]}"#
        );
    }

    #[test]
    fn bounds_and_error_types() {
        assert_eq!(PointCloud::default().bounds(), None);
        let c = PointCloud {
            points: vec![[1.0, -1.0, 5.0], [-2.0, 3.0, 4.0], [0.0, 0.0, 6.0]],
        };
        assert_eq!(c.bounds(), Some(([-2.0, -1.0, 4.0], [1.0, 3.0, 6.0])));
        let io = PointCloudError::Io {
            path: "p".into(),
            source: std::io::Error::other("x"),
        };
        let kinds: Vec<&str> = [
            io,
            PointCloudError::UnknownFormat { path: "p".into() },
            mal(PLY, "d"),
            truncated(NPY, 2, 1),
            PointCloudError::NonFinite {
                index: 0,
                axis: 0,
                value: f32::NAN,
            },
            PointCloudError::Empty,
            PointCloudError::TooFew { count: 1, min: 2 },
            PointCloudError::TooMany { count: 2, max: 1 },
        ]
        .iter()
        .map(PointCloudError::error_type)
        .collect();
        assert_eq!(
            kinds,
            [
                "io",
                "unknown_format",
                "malformed",
                "truncated",
                "non_finite",
                "empty",
                "too_few",
                "too_many"
            ]
        );
    }

    #[test]
    fn coloured_ply_is_readable_and_checks_lengths() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.ply");
        let pts = [[0.5f32, 1.0, -1.0], [2.0, 3.0, 4.0]];
        write_coloured_ply(&path, &pts, &[[255, 0, 0], [0, 128, 255]]).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert!(text.contains("property uchar red\n"), "{text}");
        assert!(text.ends_with("2.0 3.0 4.0 0 128 255\n"), "{text}");
        assert_eq!(
            PointCloud::read(&path, &Limits::default()).unwrap().points,
            pts
        );
        let err = write_coloured_ply(&path, &pts, &[[0, 0, 0]]).unwrap_err();
        assert_eq!(err.error_type(), "malformed");
        assert!(err.to_string().contains("2 points but 1 colours"), "{err}");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    // ---- property tests ----------------------------------------------------------------

    fn finite_f32() -> impl Strategy<Value = f32> {
        prop_oneof![
            -10.0f32..10.0,
            prop::num::f32::NORMAL | prop::num::f32::SUBNORMAL | prop::num::f32::ZERO,
        ]
    }

    fn cloud_strategy(max: usize) -> impl Strategy<Value = PointCloud> {
        prop::collection::vec([finite_f32(), finite_f32(), finite_f32()], 1..max)
            .prop_map(|points| PointCloud { points })
    }

    fn small_limits() -> Limits {
        Limits {
            min_points: 1,
            max_points: 4096,
        }
    }

    /// Every reader, every format: must return, never panic.
    fn feed_all(bytes: &[u8]) {
        for format in ALL {
            let _ = PointCloud::from_bytes(bytes, format, &small_limits());
            let _ = PointCloud::from_bytes(
                bytes,
                format,
                &Limits {
                    min_points: 0,
                    max_points: usize::MAX,
                },
            );
        }
    }

    fn header_strategy() -> impl Strategy<Value = Vec<u8>> {
        let count = prop_oneof![
            0u64..8,
            Just(1_000_000_000_000u64),
            Just(u64::MAX),
            any::<u64>()
        ];
        let ply = (
            prop::sample::select(vec!["ascii", "binary_little_endian", "binary_big_endian"]),
            prop::sample::select(vec![
                XYZ_FLOAT,
                "property double z\nproperty uchar q\nproperty int x\nproperty float y\n",
                "property float x\nproperty float y\nproperty float z\nproperty list uchar int l\n",
            ]),
            count.clone(),
            any::<bool>(),
        )
            .prop_map(|(enc, props, n, face)| {
                let mut h = format!("ply\nformat {enc} 1.0\nelement vertex {n}\n{props}");
                if face {
                    h.push_str("element face 3\nproperty list uchar int vertex_indices\n");
                }
                h.push_str("end_header\n");
                h.into_bytes()
            });
        let npy_header = (
            prop::sample::select(vec!["<f4", ">f4", "<f8", ">f8"]),
            any::<bool>(),
            count,
        )
            .prop_map(|(d, f, n)| npy(d, f, &format!("({n}, 3)"), &[]));
        prop_oneof![ply, npy_header, Just(b"{\"points\": [[".to_vec())]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn prop_round_trip_all_formats(cloud in cloud_strategy(64)) {
            for format in ALL {
                let back = PointCloud::from_bytes(&cloud.to_bytes(format), format, &Limits::default());
                let back = back.map_err(|e| TestCaseError::fail(format!("{format:?}: {e}")))?;
                prop_assert_eq!(bits(&back.points), bits(&cloud.points), "{:?}", format);
            }
        }

        #[test]
        fn prop_arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
            feed_all(&bytes);
            // The same bytes behind each format's magic, so they get past the first check.
            for prefix in [&b"ply\n"[..], b"ply\nformat ascii 1.0\n", b"\x93NUMPY\x01\x00"] {
                let mut v = prefix.to_vec();
                v.extend_from_slice(&bytes);
                feed_all(&v);
            }
        }

        #[test]
        fn prop_valid_header_then_garbage_never_panics(
            header in header_strategy(),
            tail in prop::collection::vec(any::<u8>(), 0..256),
        ) {
            let mut bytes = header;
            bytes.extend_from_slice(&tail);
            feed_all(&bytes);
        }

        #[test]
        fn prop_mutated_valid_files_never_panic(
            cloud in cloud_strategy(16),
            format in prop::sample::select(ALL.to_vec()),
            cut in any::<prop::sample::Index>(),
            flips in prop::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 0..6),
        ) {
            let bytes = cloud.to_bytes(format);
            let mut flipped = bytes.clone();
            for (at, xor) in &flips {
                let i = at.index(flipped.len());
                flipped[i] ^= xor;
            }
            feed_all(&flipped);
            let truncated = &bytes[..cut.index(bytes.len() + 1)];
            feed_all(truncated);
            if truncated.len() < bytes.len() && format != Format::PlyAscii && format != Format::Json {
                // Binary formats: any truncation is an error, never a silently shorter cloud.
                prop_assert!(PointCloud::from_bytes(truncated, format, &Limits::default()).is_err());
            }
        }
    }
}
