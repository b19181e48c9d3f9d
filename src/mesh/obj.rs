//! Wavefront OBJ reading (positions and faces) for imported part meshes.
//!
//! Why it exists: PartNet-Mobility stores every leaf part as `textured_objs/*.obj`. We need
//! only geometry: `v x y z` and `f` lines (any of `i`, `i/t`, `i//n`, `i/t/n`, negative
//! indices, polygons fan-triangulated). Everything else (`vt`, `vn`, `usemtl`, groups) is
//! ignored. Malformed lines are errors naming the line; out-of-range indices too.

use super::TriMesh;
use crate::mesh::MeshError;

/// Parse OBJ text into a triangle mesh.
pub fn parse(text: &str) -> Result<TriMesh, MeshError> {
    let mut mesh = TriMesh::default();
    for (ln, line) in text.lines().enumerate() {
        let line = line.trim();
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let mut p = [0f32; 3];
                for (a, v) in p.iter_mut().enumerate() {
                    let tok = it.next().ok_or_else(|| {
                        MeshError::Obj(format!(
                            "line {}: vertex has fewer than 3 coordinates",
                            ln + 1
                        ))
                    })?;
                    *v = tok.parse::<f32>().map_err(|_| {
                        MeshError::Obj(format!(
                            "line {}: coordinate {a} '{tok}' is not a number",
                            ln + 1
                        ))
                    })?;
                    if !v.is_finite() {
                        return Err(MeshError::Obj(format!(
                            "line {}: coordinate {a} is not finite",
                            ln + 1
                        )));
                    }
                }
                mesh.positions.push(p);
            }
            Some("f") => {
                let n = mesh.positions.len() as i64;
                let idx: Vec<u32> = it
                    .map(|tok| {
                        let first = tok.split('/').next().unwrap_or("");
                        let i: i64 = first.parse().map_err(|_| {
                            MeshError::Obj(format!(
                                "line {}: face index '{tok}' is not an integer",
                                ln + 1
                            ))
                        })?;
                        let k = if i < 0 { n + i } else { i - 1 };
                        if k < 0 || k >= n {
                            return Err(MeshError::Obj(format!(
                                "line {}: face index {i} out of range (1..={n})",
                                ln + 1
                            )));
                        }
                        Ok(k as u32)
                    })
                    .collect::<Result<_, MeshError>>()?;
                if idx.len() < 3 {
                    return Err(MeshError::Obj(format!(
                        "line {}: face has fewer than 3 vertices",
                        ln + 1
                    )));
                }
                for k in 1..idx.len() - 1 {
                    mesh.triangles.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok(mesh)
}

/// OBJ text of a mesh (positions and faces only).
pub fn to_text(mesh: &TriMesh) -> String {
    use std::fmt::Write;
    let mut s = String::with_capacity(mesh.positions.len() * 40 + mesh.triangles.len() * 24);
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    for t in &mesh.triangles {
        let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}

#[cfg(test)]
mod tests {
    #[test]
    fn parses_pm_style_faces_and_reports_errors() {
        let m = super::parse("# c\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1 4/1\nf -4//1 -3//1 -2//1\n").unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 2]]);
        assert_eq!(super::parse(&super::to_text(&m)).unwrap(), m);
        assert!(
            super::parse("v 0 0\n")
                .unwrap_err()
                .to_string()
                .contains("line 1")
        );
        assert!(
            super::parse("v 0 0 0\nf 1 2 3\n")
                .unwrap_err()
                .to_string()
                .contains("out of range")
        );
    }
}
