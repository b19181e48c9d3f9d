//! PLY point clouds: ASCII and binary (little and big endian) readers, hostile-input safe, and
//! the writers (plain and coloured).

#[allow(unused_imports)]
use super::*;
use std::fmt::Write as _;
use std::path::Path;

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

/// Splits input into lines (`\n`, optional `\r` before it), counting them from 1.
pub(crate) struct Lines<'a> {
    pub(crate) bytes: &'a [u8],
    pub(crate) pos: usize,
    pub(crate) line_no: usize,
}

impl<'a> Lines<'a> {
    pub(crate) fn next_line(&mut self) -> Option<&'a [u8]> {
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
    pub(crate) fn next_nonblank(&mut self) -> Option<&'a [u8]> {
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
pub(crate) enum Scalar {
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
    pub(crate) fn parse(name: &str) -> Option<Scalar> {
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

    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    pub(crate) fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes one value from the start of `b`; None if `b` is too short.
    pub(crate) fn decode(self, b: &[u8], big: bool) -> Option<f32> {
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
    pub(crate) fn parse_ascii(self, tok: &str) -> Option<f32> {
        match self {
            Scalar::F32 => tok.parse::<f32>().ok(),
            _ => tok.parse::<f64>().ok().map(|v| v as f32),
        }
    }
}

#[derive(Debug)]
pub(crate) enum Prop {
    Scalar { name: String, ty: Scalar },
    List { name: String },
}

impl Prop {
    pub(crate) fn name(&self) -> &str {
        match self {
            Prop::Scalar { name, .. } | Prop::List { name, .. } => name,
        }
    }
}

#[derive(Debug)]
pub(crate) struct Element {
    pub(crate) name: String,
    pub(crate) count: u64,
    pub(crate) props: Vec<Prop>,
    pub(crate) line: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Encoding {
    Ascii,
    BinaryLe,
    BinaryBe,
}

pub(crate) fn ply_header<'a>(
    bytes: &'a [u8],
) -> Result<(Encoding, Vec<Element>, Lines<'a>), PointCloudError> {
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

pub(crate) fn ply_read(bytes: &[u8], limits: &Limits) -> Result<Vec<[f32; 3]>, PointCloudError> {
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

pub(crate) fn ply_read_binary(
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

pub(crate) fn ply_read_ascii(
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

pub(crate) fn ply_write(points: &[[f32; 3]], ascii: bool) -> Vec<u8> {
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
