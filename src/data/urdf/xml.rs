//! A small XML element tree with line numbers, over `quick-xml`.
//!
//! Why it exists: a malformed URDF must be reported with its file, line and element, and the
//! URDF reader wants to walk elements (`robot/link/visual/geometry/mesh`) rather than events.
//! `quick-xml` (already in the dependency tree through `urdf-rs`) gives byte offsets; this
//! module builds the tree and turns offsets into 1-based line numbers. Text content, comments,
//! processing instructions and namespaces are ignored (URDF keeps everything in attributes).

use std::path::{Path, PathBuf};

use quick_xml::events::{BytesStart, Event};

use super::UrdfError;

/// One XML element.
#[derive(Debug, Clone, PartialEq)]
pub struct Element {
    /// Tag name.
    pub name: String,
    /// Attributes in document order (unescaped values).
    pub attrs: Vec<(String, String)>,
    /// Child elements in document order.
    pub children: Vec<Element>,
    /// 1-based line of the start tag.
    pub line: usize,
}

impl Element {
    /// The value of attribute `key`.
    pub fn attr(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// Child elements named `name`.
    pub fn children_named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Element> + 'a {
        self.children.iter().filter(move |c| c.name == name)
    }

    /// The first child element named `name`.
    pub fn child(&self, name: &str) -> Option<&Element> {
        self.children.iter().find(|c| c.name == name)
    }
}

/// 1-based line of byte `offset` in `text`.
pub fn line_of(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

fn element(
    path: &Path,
    text: &str,
    start: &BytesStart<'_>,
    offset: usize,
) -> Result<Element, UrdfError> {
    let line = line_of(text, offset);
    let name = String::from_utf8_lossy(start.name().as_ref()).into_owned();
    let mut attrs = Vec::new();
    for a in start.attributes() {
        let a = a.map_err(|e| UrdfError::xml(path, line, &name, format!("bad attribute: {e}")))?;
        let key = String::from_utf8_lossy(a.key.as_ref()).into_owned();
        let value = a
            .unescape_value()
            .map_err(|e| UrdfError::xml(path, line, &name, format!("attribute {key}: {e}")))?
            .into_owned();
        attrs.push((key, value));
    }
    Ok(Element {
        name,
        attrs,
        children: Vec::new(),
        line,
    })
}

/// Parse `text` (the contents of `path`) into its root element.
pub fn parse(path: &Path, text: &str) -> Result<Element, UrdfError> {
    let mut reader = quick_xml::Reader::from_str(text);
    reader.config_mut().check_end_names = true;
    let mut stack: Vec<Element> = Vec::new();
    let mut root: Option<Element> = None;
    loop {
        let before = reader.buffer_position() as usize;
        let event = reader.read_event().map_err(|e| {
            let at = reader.error_position() as usize;
            let open = stack
                .last()
                .map(|e| e.name.clone())
                .unwrap_or_else(|| "document".into());
            UrdfError::xml(path, line_of(text, at), &open, format!("XML syntax: {e}"))
        })?;
        // The start tag's '<' is the first non-blank byte after the previous event.
        let tag_at = before
            + text.as_bytes()[before.min(text.len())..]
                .iter()
                .take_while(|b| b.is_ascii_whitespace())
                .count();
        match event {
            Event::Start(s) => stack.push(element(path, text, &s, tag_at)?),
            Event::Empty(s) => {
                let e = element(path, text, &s, tag_at)?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(e),
                    None if root.is_none() => root = Some(e),
                    None => {
                        return Err(UrdfError::xml(
                            path,
                            e.line,
                            &e.name,
                            "a second root element",
                        ));
                    }
                }
            }
            Event::End(_) => {
                let Some(done) = stack.pop() else {
                    return Err(UrdfError::xml(
                        path,
                        line_of(text, tag_at),
                        "document",
                        "closing tag without an opening tag",
                    ));
                };
                match stack.last_mut() {
                    Some(parent) => parent.children.push(done),
                    None if root.is_none() => root = Some(done),
                    None => {
                        return Err(UrdfError::xml(
                            path,
                            done.line,
                            &done.name,
                            "a second root element",
                        ));
                    }
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if let Some(open) = stack.last() {
        return Err(UrdfError::xml(
            path,
            open.line,
            &open.name,
            "element is never closed (unexpected end of file)",
        ));
    }
    root.ok_or_else(|| UrdfError::xml(path, 1, "document", "no root element"))
}

/// Read and parse an XML file.
pub fn read(path: &Path) -> Result<(Element, String), UrdfError> {
    let bytes = std::fs::read(path).map_err(|source| UrdfError::Io {
        path: PathBuf::from(path),
        source,
    })?;
    let text = String::from_utf8(bytes)
        .map_err(|e| UrdfError::xml(path, 1, "document", format!("not UTF-8: {e}")))?;
    let root = parse(path, &text)?;
    Ok((root, text))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builds_a_tree_with_lines() {
        let t = "<?xml version=\"1.0\"?>\n<robot name=\"r\">\n  <link name=\"a\">\n    <visual/>\n  </link>\n</robot>\n";
        let r = parse(Path::new("x.urdf"), t).unwrap();
        assert_eq!(r.name, "robot");
        assert_eq!(r.line, 2);
        assert_eq!(r.attr("name"), Some("r"));
        let l = r.child("link").unwrap();
        assert_eq!(l.line, 3);
        assert_eq!(l.children[0].line, 4);
    }

    #[test]
    fn reports_mismatched_and_unclosed_tags() {
        let e = parse(
            Path::new("x.urdf"),
            "<robot>\n<link name=\"a\">\n</joint>\n</robot>",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("x.urdf:3"), "{e}");
        assert!(e.contains("<link>"), "{e}");
        let e = parse(Path::new("x.urdf"), "<robot>\n<link name=\"a\">\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.urdf:2") && e.contains("<link>"), "{e}");
    }
}
