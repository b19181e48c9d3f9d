//! STL reading (ASCII and binary) for imported URDF meshes.
//!
//! Why it exists: URDF assets (ROS packages, the PRPL lab kitchen) store link geometry as STL,
//! which has no vertex sharing; physnap's importer wants an indexed [`TriMesh`]. Binary is
//! recognised by its size (80-byte header, u32 count, 50 bytes per triangle), whatever the
//! header says (many binary files start with "solid"); otherwise the text must be ASCII STL.
//! Identical vertices are merged (exact bit equality), so the result is the same mesh however
//! it was stored. Errors name the triangle or line.

use std::collections::HashMap;

use super::TriMesh;

/// A file that is not a readable STL (what is wrong, with the triangle or line).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct StlError(pub String);

#[derive(Default)]
struct Builder {
    mesh: TriMesh,
    index: HashMap<[u32; 3], u32>,
}

impl Builder {
    fn vertex(&mut self, p: [f32; 3]) -> u32 {
        // -0.0 and 0.0 are the same point.
        let key = p.map(|v| if v == 0.0 { 0 } else { v.to_bits() });
        *self.index.entry(key).or_insert_with(|| {
            self.mesh.positions.push(p);
            (self.mesh.positions.len() - 1) as u32
        })
    }

    fn triangle(&mut self, t: [[f32; 3]; 3]) {
        let i = t.map(|p| self.vertex(p));
        if i[0] != i[1] && i[1] != i[2] && i[0] != i[2] {
            self.mesh.triangles.push(i);
        }
    }
}

/// Parse STL bytes (ASCII or binary).
pub fn parse(bytes: &[u8]) -> Result<TriMesh, StlError> {
    parse_any(bytes)
}

impl From<String> for StlError {
    fn from(s: String) -> Self {
        StlError(s)
    }
}

fn parse_any(bytes: &[u8]) -> Result<TriMesh, StlError> {
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if n.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(bytes.len()) {
            return parse_binary(bytes, n);
        }
    }
    let text = std::str::from_utf8(bytes).map_err(|_| {
        "neither binary STL (size does not match the triangle count) nor ASCII text".to_string()
    })?;
    if !text.trim_start().starts_with("solid") {
        return Err(StlError(
            "neither binary STL (size does not match the triangle count) nor ASCII STL (no 'solid')"
                .into(),
        ));
    }
    parse_ascii(text)
}

fn parse_binary(bytes: &[u8], n: usize) -> Result<TriMesh, StlError> {
    let mut b = Builder::default();
    for k in 0..n {
        let rec = &bytes[84 + 50 * k..84 + 50 * (k + 1)];
        let f = |i: usize| f32::from_le_bytes([rec[i], rec[i + 1], rec[i + 2], rec[i + 3]]);
        let mut t = [[0f32; 3]; 3];
        for (v, p) in t.iter_mut().enumerate() {
            for (a, c) in p.iter_mut().enumerate() {
                *c = f(12 + 12 * v + 4 * a);
                if !c.is_finite() {
                    return Err(StlError(format!("triangle {k}: vertex {v} is not finite")));
                }
            }
        }
        b.triangle(t);
    }
    Ok(b.mesh)
}

fn parse_ascii(text: &str) -> Result<TriMesh, StlError> {
    let mut b = Builder::default();
    let mut pending: Vec<[f32; 3]> = Vec::with_capacity(3);
    for (ln, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("vertex") => {
                let mut p = [0f32; 3];
                for (a, c) in p.iter_mut().enumerate() {
                    let tok = it.next().ok_or_else(|| {
                        format!("line {}: vertex has fewer than 3 coordinates", ln + 1)
                    })?;
                    *c = tok
                        .parse::<f32>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| {
                            format!("line {}: coordinate {a} {tok:?} is not a number", ln + 1)
                        })?;
                }
                pending.push(p);
            }
            Some("endloop") => {
                if pending.len() < 3 {
                    return Err(StlError(format!(
                        "line {}: facet with {} vertices",
                        ln + 1,
                        pending.len()
                    )));
                }
                for k in 1..pending.len() - 1 {
                    b.triangle([pending[0], pending[k], pending[k + 1]]);
                }
                pending.clear();
            }
            _ => {}
        }
    }
    if !pending.is_empty() {
        return Err(StlError("unterminated facet at end of file".into()));
    }
    Ok(b.mesh)
}

/// Binary STL bytes of a mesh (zero normals; readers recompute them).
pub fn to_binary(mesh: &TriMesh) -> Vec<u8> {
    let mut out = vec![0u8; 80];
    out.extend_from_slice(&(mesh.triangles.len() as u32).to_le_bytes());
    for t in &mesh.triangles {
        out.extend_from_slice(&[0u8; 12]);
        for &i in t {
            for c in mesh.positions[i as usize] {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        out.extend_from_slice(&[0u8; 2]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> TriMesh {
        TriMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn binary_round_trip_even_with_a_solid_header() {
        let m = tetra();
        let mut bytes = to_binary(&m);
        bytes[..5].copy_from_slice(b"solid");
        let corners = |m: &TriMesh| -> Vec<[[f32; 3]; 3]> {
            m.triangles
                .iter()
                .map(|t| t.map(|i| m.positions[i as usize]))
                .collect()
        };
        let back = parse(&bytes).unwrap();
        assert_eq!(back.positions.len(), 4);
        assert_eq!(corners(&back), corners(&m));
    }

    #[test]
    fn ascii_facets_share_vertices() {
        let text = "solid t\nfacet normal 0 0 -1\n outer loop\n  vertex 0 0 0\n  vertex 0 1 0\n  vertex 1 0 0\n endloop\nendfacet\nfacet normal 0 -1 0\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  vertex 0 0 1\n endloop\nendfacet\nendsolid t\n";
        let m = parse(text.as_bytes()).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        let e = parse(b"solid t\nouter loop\nvertex 0 x 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3"), "{e}");
        assert!(parse(b"garbage").is_err());
    }
}
