//! Write a [`BuiltObject`] as a PartNet-Mobility-layout folder, so the one importer reads it.
//!
//! Why it exists: physnap has a single importer pipeline (`data::partnet::read_object` →
//! `data::dataset`). A URDF object is written exactly like a PartNet-Mobility object
//! (data.md §A): one `mobility_v2.json` entry and one `textured_objs/original-<k>.obj` per
//! merged part, in PartNet-Mobility's raw Y-up frame (the canonical frame mapped by
//! `partnet::world_to_raw`, a signed permutation, so the round trip is exact), hinge limits in
//! degrees, slider limits in metres, plus `meta.json` (`model_cat`), `result.json`,
//! `semantics.txt`, a `mobility.urdf` in PartNet-Mobility's conventions, and `source.json`
//! (where the object came from and its source → canonical transform).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use serde_json::{Value, json};

use super::UrdfError;
use super::convert::BuiltObject;
use crate::data::partnet::world_to_raw;
use crate::mesh::obj;
use crate::object::JointKind;

fn write(path: &Path, bytes: impl AsRef<[u8]>) -> Result<(), UrdfError> {
    std::fs::write(path, bytes).map_err(|source| UrdfError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Write `obj` into `dir/<id>/`. `source` is stored as `source.json`.
pub fn write_object(
    obj: &BuiltObject,
    id: &str,
    category: &str,
    source: &Value,
    dir: &Path,
) -> Result<PathBuf, UrdfError> {
    let root = dir.join(id);
    let objs = root.join("textured_objs");
    std::fs::create_dir_all(&objs).map_err(|source| UrdfError::Io {
        path: objs.clone(),
        source,
    })?;
    let label = |k: usize| -> String {
        let l = &obj.parts[k].links[0];
        l.strip_suffix("_link").unwrap_or(l).to_string()
    };
    let joint_of = |k: usize| obj.joints.iter().find(|j| j.child == k);
    let mut entries = Vec::new();
    let mut children = Vec::new();
    let mut semantics = String::new();
    for (k, part) in obj.parts.iter().enumerate() {
        let raw = part.mesh.clone().map_positions(|v| {
            let r = world_to_raw(&Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64));
            [r[0] as f32, r[1] as f32, r[2] as f32]
        });
        write(&objs.join(format!("original-{k}.obj")), obj::to_text(&raw))?;
        children.push(json!({
            "id": k + 1, "text": label(k), "name": label(k), "objs": [format!("original-{k}")],
        }));
        let (word, parent, data) = match joint_of(k) {
            None => ("heavy", -1i64, json!({})),
            Some(j) => {
                let axis = json!({
                    "origin": world_to_raw(&j.origin.coords),
                    "direction": world_to_raw(&j.axis),
                });
                match j.kind {
                    JointKind::Prismatic => (
                        "slider",
                        j.parent as i64,
                        json!({ "axis": axis, "limit": { "a": j.range[0], "b": j.range[1], "noLimit": false } }),
                    ),
                    _ => (
                        "hinge",
                        j.parent as i64,
                        json!({ "axis": axis, "limit": {
                            "a": j.range[0].to_degrees(), "b": j.range[1].to_degrees(), "noLimit": false } }),
                    ),
                }
            }
        };
        entries.push(json!({
            "id": k, "parent": parent, "joint": word, "name": label(k),
            "parts": [{ "id": k + 1, "name": label(k), "children": [] }],
            "jointData": data, "links": part.links,
        }));
        let _ = writeln!(semantics, "link_{k} {word} {}", label(k));
    }
    let result = json!([{ "id": 0, "text": category, "name": category.to_lowercase(), "children": children }]);
    let meta = json!({
        "model_id": format!("physnap-urdf-{id}"), "anno_id": id, "model_cat": category,
        "version": "physnap-urdf-1", "units": "metres",
    });
    let text = |v: &Value| serde_json::to_string_pretty(v).unwrap_or_default();
    write(&root.join("mobility_v2.json"), text(&Value::Array(entries)))?;
    write(&root.join("result.json"), text(&result))?;
    write(&root.join("meta.json"), text(&meta))?;
    write(&root.join("semantics.txt"), semantics)?;
    write(&root.join("source.json"), text(source))?;
    write(&root.join("mobility.urdf"), mobility_urdf(obj, id))?;
    Ok(root)
}

/// PartNet-Mobility-style URDF: base + fixed Y-up→Z-up joint, link frames at joint origins.
fn mobility_urdf(obj: &BuiltObject, id: &str) -> String {
    let frame = |k: usize| -> [f64; 3] {
        obj.joints
            .iter()
            .find(|j| j.child == k)
            .map(|j| world_to_raw(&j.origin.coords))
            .unwrap_or([0.0; 3])
    };
    let mut x =
        format!("<?xml version=\"1.0\" ?>\n<robot name=\"{id}\">\n\t<link name=\"base\"/>\n");
    for k in 0..obj.parts.len() {
        let f = frame(k);
        let _ = writeln!(x, "\t<link name=\"link_{k}\">");
        for tag in ["visual", "collision"] {
            let _ = writeln!(
                x,
                "\t\t<{tag}>\n\t\t\t<origin xyz=\"{} {} {}\"/>\n\t\t\t<geometry>\n\t\t\t\t<mesh filename=\"textured_objs/original-{k}.obj\"/>\n\t\t\t</geometry>\n\t\t</{tag}>",
                -f[0], -f[1], -f[2]
            );
        }
        let _ = writeln!(x, "\t</link>");
        match obj.joints.iter().find(|j| j.child == k) {
            None => {
                let _ = writeln!(
                    x,
                    "\t<joint name=\"joint_{k}\" type=\"fixed\">\n\t\t<origin rpy=\"1.570796326794897 0 -1.570796326794897\" xyz=\"0 0 0\"/>\n\t\t<child link=\"link_{k}\"/>\n\t\t<parent link=\"base\"/>\n\t</joint>"
                );
            }
            Some(j) => {
                let pf = frame(j.parent);
                let d = world_to_raw(&j.axis);
                let ty = match j.kind {
                    JointKind::Prismatic => "prismatic",
                    _ => "revolute",
                };
                let _ = writeln!(
                    x,
                    "\t<joint name=\"joint_{k}\" type=\"{ty}\">\n\t\t<origin xyz=\"{} {} {}\"/>\n\t\t<axis xyz=\"{} {} {}\"/>\n\t\t<child link=\"link_{k}\"/>\n\t\t<parent link=\"link_{}\"/>\n\t\t<limit lower=\"{}\" upper=\"{}\"/>\n\t</joint>",
                    f[0] - pf[0],
                    f[1] - pf[1],
                    f[2] - pf[2],
                    d[0],
                    d[1],
                    d[2],
                    j.parent,
                    j.range[0],
                    j.range[1]
                );
            }
        }
    }
    x.push_str("</robot>\n");
    x
}
