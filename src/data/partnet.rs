//! The PartNet-Mobility on-disk layout: writer (for synthetic objects) and reader (importer).
//!
//! Why it exists: one importer must serve both real PartNet-Mobility and our procedural data,
//! so synthetic objects are written exactly as PartNet-Mobility stores objects (data.md §A):
//!
//! ```text
//! <id>/mobility.urdf        base link + fixed Y-up→Z-up joint; link_i frames at their joint
//!                           origin; <limit> with lower/upper only (PM's quirk)
//! <id>/mobility_v2.json     [{id, parent, joint: hinge|slider|heavy|static, name, parts,
//!                            jointData: {axis: {origin, direction}, limit: {a, b, noLimit,
//!                            rotates?, rotationLimit?}}}], raw frame, hinge limits in DEGREES
//! <id>/result.json          semantic tree; leaves list their objs
//! <id>/meta.json            {model_id, anno_id, model_cat, version}
//! <id>/semantics.txt        "link_<i> <joint> <label>"
//! <id>/textured_objs/original-<n>.obj   one closed mesh per primitive, raw frame
//! <id>/physnap_shapes.json  (synthetic only) the object JSON with exact analytic shapes
//! ```
//!
//! Raw frame: PartNet-Mobility meshes are Y-up; its URDF's base joint (rpy π/2, 0, −π/2) maps
//! raw (x, y, z) ↦ world (−z, −x, y). That is a signed permutation, so the conversion in both
//! directions is exact in floating point.
//!
//! The reader follows the importer checklist (data.md §A.5): `mobility_v2.json` +
//! `result.json` are primary; hinge degrees → radians; `noLimit` → [0, 2π]; `rotates` → screw;
//! `free`/`heavy`/`static`/`junk`/`fixed` → fixed; several roots are merged into the first;
//! `null` or zero axes and missing `meta.json` make the object unusable (a clear reason);
//! missing OBJ files are skipped (PM keeps references to deleted 0-face parts); fixed children
//! are merged into their parents; objects with < 2 or > 8 nodes are refused.

use crate::error::CoreError;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};
use serde_json::{Value, json};

use super::{DataError, LabelledObject};
use crate::mesh::{TriMesh, obj, primitives::append_primitive};
use crate::object::{ArticulatedObject, Joint, JointKind, MAX_PARTS, Part};
use crate::shape::{PartShape, Primitive};

/// Raw PartNet-Mobility (Y-up) → physnap object frame (Z-up).
pub fn raw_to_world(v: [f64; 3]) -> Vector3<f64> {
    Vector3::new(-v[2], -v[0], v[1])
}

/// physnap object frame → raw PartNet-Mobility frame.
pub fn world_to_raw(v: &Vector3<f64>) -> [f64; 3] {
    [-v.y, v.z, -v.x]
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> DataError + '_ {
    move |source| DataError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn joint_word(kind: JointKind, is_root: bool) -> &'static str {
    if is_root {
        return "heavy";
    }
    match kind {
        JointKind::Revolute => "hinge",
        JointKind::Prismatic | JointKind::Screw => "slider",
        JointKind::Fixed => "static",
    }
}

/// Write `obj` in the PartNet-Mobility layout into `dir/<id>/`. Returns the folder.
pub fn write_object(obj: &LabelledObject, id: &str, dir: &Path) -> Result<PathBuf, DataError> {
    let o = &obj.object;
    o.validate()?;
    let root_dir = dir.join(id);
    let objs_dir = root_dir.join("textured_objs");
    std::fs::create_dir_all(&objs_dir).map_err(io(&objs_dir))?;
    let category = o.category.clone().unwrap_or_else(|| "Unknown".into());
    let root = o.root();

    // Meshes: one OBJ per primitive (raw frame), grouped per part in result.json.
    let mut next_obj = 0usize;
    let mut result_children = Vec::new();
    let mut part_node_id = Vec::with_capacity(o.parts.len());
    for (p, part) in o.parts.iter().enumerate() {
        let prims: Vec<Primitive> = match &part.shape {
            PartShape::Primitives(list) => list.clone(),
            PartShape::Box => vec![Primitive::Cuboid {
                center: Vector3::zeros(),
                half_extents: part.half_extents,
            }],
            PartShape::Latent(_) => {
                return Err(DataError::Malformed {
                    path: root_dir.clone(),
                    detail: format!(
                        "part {:?} has a latent shape; only analytic parts can be written",
                        part.name
                    ),
                });
            }
        };
        let mut leaves = Vec::new();
        for prim in &prims {
            let mut m = TriMesh::default();
            append_primitive(&mut m, prim, &part.center);
            let raw = m.map_positions(|v| {
                let r = world_to_raw(&Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64));
                [r[0] as f32, r[1] as f32, r[2] as f32]
            });
            let name = format!("original-{next_obj}");
            next_obj += 1;
            let path = objs_dir.join(format!("{name}.obj"));
            std::fs::write(&path, obj::to_text(&raw)).map_err(io(&path))?;
            leaves.push(name);
        }
        // result.json node ids: 0 is the object, part p is node p + 1.
        let node_id = p + 1;
        part_node_id.push(node_id);
        result_children.push(json!({
            "id": node_id, "text": obj.labels[p], "name": obj.labels[p], "objs": leaves,
        }));
    }
    let result = json!([{ "id": 0, "text": category, "name": category.to_lowercase(), "children": result_children }]);

    // mobility_v2.json: entry id = part index (link_<p>).
    let mut entries = Vec::new();
    let mut semantics = String::new();
    for (p, node_id) in part_node_id.iter().enumerate() {
        let joint = o.parent_joint(p).map(|k| &o.joints[k]);
        let kind = joint.map(|j| j.kind).unwrap_or(JointKind::Fixed);
        let word = joint_word(kind, p == root);
        let joint_data = match joint {
            Some(j) if kind != JointKind::Fixed => {
                let axis = json!({
                    "origin": world_to_raw(&j.origin.coords),
                    "direction": world_to_raw(&j.axis),
                });
                let limit = match kind {
                    JointKind::Revolute => json!({
                        "a": j.revolute[0].to_degrees(), "b": j.revolute[1].to_degrees(), "noLimit": false,
                    }),
                    JointKind::Prismatic => {
                        json!({ "a": j.prismatic[0], "b": j.prismatic[1], "noLimit": false })
                    }
                    _ => json!({
                        "a": j.prismatic[0], "b": j.prismatic[1], "noLimit": false, "rotates": true,
                        "noRotationLimit": false,
                        "rotationLimit": j.revolute[1].to_degrees(),
                        "rotationLimitLower": j.revolute[0].to_degrees(),
                    }),
                };
                json!({ "axis": axis, "limit": limit })
            }
            _ => json!({}),
        };
        entries.push(json!({
            "id": p,
            "parent": joint.map(|j| j.parent as i64).unwrap_or(-1),
            "joint": word,
            "name": obj.labels[p],
            "parts": [{ "id": node_id, "name": obj.labels[p], "children": [] }],
            "jointData": joint_data,
        }));
        let _ = writeln!(semantics, "link_{p} {word} {}", obj.labels[p]);
    }

    let meta = json!({
        "model_id": format!("physnap-{id}"), "anno_id": id, "model_cat": category,
        "version": "physnap-synth-1", "units": "metres",
    });
    let write_json = |name: &str, v: &Value| -> Result<(), DataError> {
        let path = root_dir.join(name);
        // Serialising a serde_json::Value cannot fail.
        std::fs::write(&path, serde_json::to_string(v).unwrap_or_default()).map_err(io(&path))
    };
    write_json("mobility_v2.json", &Value::Array(entries))?;
    write_json("result.json", &result)?;
    write_json("meta.json", &meta)?;
    let sem_path = root_dir.join("semantics.txt");
    std::fs::write(&sem_path, semantics).map_err(io(&sem_path))?;
    let urdf_path = root_dir.join("mobility.urdf");
    std::fs::write(&urdf_path, mobility_urdf(obj, &result_children)).map_err(io(&urdf_path))?;
    let shapes_path = root_dir.join("physnap_shapes.json");
    std::fs::write(&shapes_path, crate::io::object_json::to_string(o)).map_err(io(&shapes_path))?;
    Ok(root_dir)
}

/// A PartNet-Mobility-style URDF (raw frame, degrees converted, no effort/velocity).
fn mobility_urdf(obj: &LabelledObject, result_children: &[Value]) -> String {
    let o = &obj.object;
    let frame = |p: usize| -> [f64; 3] {
        o.parent_joint(p)
            .map(|k| world_to_raw(&o.joints[k].origin.coords))
            .unwrap_or([0.0; 3])
    };
    let mut x = String::new();
    let _ = writeln!(
        x,
        "<?xml version=\"1.0\" ?>\n<robot name=\"partnet_{}\">",
        o.name
    );
    let _ = writeln!(x, "\t<link name=\"base\"/>");
    for (p, leaves) in result_children.iter().enumerate() {
        let f = frame(p);
        let _ = writeln!(x, "\t<link name=\"link_{p}\">");
        for leaf in leaves["objs"].as_array().into_iter().flatten() {
            let name = leaf.as_str().unwrap_or_default();
            for tag in ["visual", "collision"] {
                let _ = writeln!(
                    x,
                    "\t\t<{tag} name=\"{}\">\n\t\t\t<origin xyz=\"{} {} {}\"/>\n\t\t\t<geometry>\n\t\t\t\t<mesh filename=\"textured_objs/{name}.obj\"/>\n\t\t\t</geometry>\n\t\t</{tag}>",
                    obj.labels[p], -f[0], -f[1], -f[2]
                );
            }
        }
        let _ = writeln!(x, "\t</link>");
        match o.parent_joint(p) {
            None => {
                let _ = writeln!(
                    x,
                    "\t<joint name=\"joint_{p}\" type=\"fixed\">\n\t\t<origin rpy=\"1.570796326794897 0 -1.570796326794897\" xyz=\"0 0 0\"/>\n\t\t<child link=\"link_{p}\"/>\n\t\t<parent link=\"base\"/>\n\t</joint>"
                );
            }
            Some(k) => {
                let j = &o.joints[k];
                let pf = frame(j.parent);
                let d = world_to_raw(&j.axis);
                let (ty, limit) = match j.kind {
                    JointKind::Revolute => ("revolute", Some(j.revolute)),
                    JointKind::Prismatic | JointKind::Screw => ("prismatic", Some(j.prismatic)),
                    JointKind::Fixed => ("fixed", None),
                };
                let _ = writeln!(
                    x,
                    "\t<joint name=\"joint_{p}\" type=\"{ty}\">\n\t\t<origin xyz=\"{} {} {}\"/>\n\t\t<axis xyz=\"{} {} {}\"/>\n\t\t<child link=\"link_{p}\"/>\n\t\t<parent link=\"link_{}\"/>",
                    f[0] - pf[0],
                    f[1] - pf[1],
                    f[2] - pf[2],
                    d[0],
                    d[1],
                    d[2],
                    j.parent
                );
                if let Some(r) = limit {
                    let _ = writeln!(x, "\t\t<limit lower=\"{}\" upper=\"{}\"/>", r[0], r[1]);
                }
                let _ = writeln!(x, "\t</joint>");
            }
        }
    }
    let _ = writeln!(x, "</robot>");
    x
}

/// An object read from a PartNet-Mobility folder, fixed children merged.
#[derive(Debug, Clone)]
pub struct ImportedObject {
    /// Folder name / `anno_id`.
    pub id: String,
    /// Canonical category name (from `meta.json` `model_cat`).
    pub category: String,
    /// The merged object (object frame, Z-up). Parts carry exact primitives when the folder
    /// has `physnap_shapes.json`, otherwise `PartShape::Box` (geometry is in `meshes`).
    pub object: ArticulatedObject,
    /// Semantic label per merged part (the movable link's label).
    pub labels: Vec<String>,
    /// Mesh per merged part, object frame at rest.
    pub meshes: Vec<TriMesh>,
    /// Whether the shapes are exact analytic SDFs.
    pub analytic: bool,
    /// Non-fatal oddities met while reading (missing OBJ files, extra roots, ...).
    pub notes: Vec<String>,
}

fn malformed(path: &Path, detail: impl Into<String>) -> DataError {
    DataError::Malformed {
        path: path.to_path_buf(),
        detail: detail.into(),
    }
}

fn read_json(path: &Path) -> Result<Value, DataError> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    serde_json::from_str(&text).map_err(|e| malformed(path, format!("invalid JSON: {e}")))
}

fn vec3(v: &Value) -> Option<[f64; 3]> {
    let a = v.as_array()?;
    if a.len() != 3 {
        return None;
    }
    let mut out = [0.0; 3];
    for (o, x) in out.iter_mut().zip(a) {
        *o = x.as_f64()?;
        if !o.is_finite() {
            return None;
        }
    }
    Some(out)
}

fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Number(n) => n.as_f64(),
        // Mirrors have corrupted numbers stored as strings; accept clean ones only.
        Value::String(s) => s.trim().parse().ok(),
        _ => None,
    }
    .filter(|x: &f64| x.is_finite())
}

/// Collect every `objs` name under a result.json node.
fn collect_objs(node: &Value, out: &mut Vec<String>) {
    if let Some(objs) = node["objs"].as_array() {
        out.extend(objs.iter().filter_map(|o| o.as_str().map(String::from)));
    }
    if let Some(children) = node["children"].as_array() {
        for c in children {
            collect_objs(c, out);
        }
    }
}

fn index_result(node: &Value, map: &mut HashMap<i64, Vec<String>>) {
    if let Some(id) = node["id"].as_i64() {
        let mut objs = Vec::new();
        collect_objs(node, &mut objs);
        map.insert(id, objs);
    }
    if let Some(children) = node["children"].as_array() {
        for c in children {
            index_result(c, map);
        }
    }
}

/// Read one PartNet-Mobility object folder.
pub fn read_object(dir: &Path) -> Result<ImportedObject, DataError> {
    let id = dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let meta = read_json(&dir.join("meta.json"))?;
    let category = meta["model_cat"]
        .as_str()
        .ok_or_else(|| malformed(&dir.join("meta.json"), "no model_cat"))?;
    let category = super::categories::canonical_name(category)
        .ok_or_else(|| {
            malformed(
                &dir.join("meta.json"),
                format!("unknown model_cat {category:?}"),
            )
        })?
        .to_string();
    let mob_path = dir.join("mobility_v2.json");
    let mob = read_json(&mob_path)?;
    let entries = mob
        .as_array()
        .ok_or_else(|| malformed(&mob_path, "expected a JSON list of links"))?;
    let mut result_index = HashMap::new();
    let result_path = dir.join("result.json");
    match read_json(&result_path)? {
        Value::Array(roots) => roots
            .iter()
            .for_each(|r| index_result(r, &mut result_index)),
        other => index_result(&other, &mut result_index),
    }
    let mut notes = Vec::new();

    // Links in file order; ids may be arbitrary integers.
    struct Link {
        id: i64,
        parent: i64,
        kind: JointKind,
        axis: Option<(Vector3<f64>, Point3<f64>)>,
        revolute: [f64; 2],
        prismatic: [f64; 2],
        label: String,
        mesh: TriMesh,
    }
    let mut links = Vec::with_capacity(entries.len());
    for (k, e) in entries.iter().enumerate() {
        let at = |what: &str| format!("links[{k}] (id {}): {what}", e["id"]);
        let lid = e["id"]
            .as_i64()
            .ok_or_else(|| malformed(&mob_path, at("no integer id")))?;
        let parent = e["parent"].as_i64().unwrap_or(-1);
        let word = e["joint"].as_str().unwrap_or("static");
        let limit = &e["jointData"]["limit"];
        let (mut kind, mut revolute, mut prismatic) = (JointKind::Fixed, [0.0; 2], [0.0; 2]);
        let ab = || -> Result<[f64; 2], DataError> {
            let a = number(&limit["a"])
                .ok_or_else(|| malformed(&mob_path, at("limit.a missing or not a number")))?;
            let b = number(&limit["b"])
                .ok_or_else(|| malformed(&mob_path, at("limit.b missing or not a number")))?;
            Ok([a.min(b), a.max(b)])
        };
        match word {
            "hinge" if parent >= 0 => {
                kind = JointKind::Revolute;
                revolute = if limit["noLimit"].as_bool() == Some(true) {
                    [0.0, std::f64::consts::TAU]
                } else {
                    let r = ab()?;
                    [r[0].to_radians(), r[1].to_radians()]
                };
            }
            "slider" if parent >= 0 => {
                prismatic = ab()?;
                kind = JointKind::Prismatic;
                if limit["rotates"].as_bool() == Some(true) {
                    kind = JointKind::Screw;
                    revolute = if limit["noRotationLimit"].as_bool() == Some(true) {
                        [0.0, std::f64::consts::TAU]
                    } else {
                        let hi = number(&limit["rotationLimit"]).unwrap_or(360.0);
                        let lo = number(&limit["rotationLimitLower"]).unwrap_or(0.0);
                        [lo.min(hi).to_radians(), lo.max(hi).to_radians()]
                    };
                }
            }
            _ => {}
        }
        let axis = if kind != JointKind::Fixed {
            let ax = &e["jointData"]["axis"];
            let dir_raw = vec3(&ax["direction"]).ok_or_else(|| {
                malformed(
                    &mob_path,
                    at("joint axis direction is null or not 3 numbers (bad data)"),
                )
            })?;
            let origin_raw = vec3(&ax["origin"]).ok_or_else(|| {
                malformed(
                    &mob_path,
                    at("joint axis origin is null or not 3 numbers (bad data)"),
                )
            })?;
            let d = raw_to_world(dir_raw);
            if d.norm() < 1e-9 {
                return Err(malformed(&mob_path, at("joint axis direction is zero")));
            }
            Some((d.normalize(), Point3::from(raw_to_world(origin_raw))))
        } else {
            None
        };
        // Mesh: every obj under every referenced result node.
        let mut names = Vec::new();
        for part in e["parts"].as_array().into_iter().flatten() {
            if let Some(pid) = part["id"].as_i64() {
                names.extend(result_index.get(&pid).cloned().unwrap_or_default());
            }
        }
        names.sort();
        names.dedup();
        let mut mesh = TriMesh::default();
        for name in names {
            let path = dir.join("textured_objs").join(format!("{name}.obj"));
            let text = match std::fs::read_to_string(&path) {
                Ok(t) => t,
                Err(_) => {
                    notes.push(format!("missing mesh {} (skipped)", path.display()));
                    continue;
                }
            };
            let m = obj::parse(&text).map_err(|d| malformed(&path, d.to_string()))?;
            let base = mesh.positions.len() as u32;
            mesh.positions.extend(m.positions.iter().map(|v| {
                let w = raw_to_world([v[0] as f64, v[1] as f64, v[2] as f64]);
                [w.x as f32, w.y as f32, w.z as f32]
            }));
            mesh.triangles.extend(
                m.triangles
                    .iter()
                    .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
            );
        }
        links.push(Link {
            id: lid,
            parent,
            kind,
            axis,
            revolute,
            prismatic,
            label: e["name"].as_str().unwrap_or("part").to_string(),
            mesh,
        });
    }
    if links.is_empty() {
        return Err(malformed(&mob_path, "no links"));
    }
    // Roots: parent -1 (or a parent id that does not exist). Extra roots merge into the first.
    let pos = |lid: i64| links.iter().position(|l| l.id == lid);
    let roots: Vec<usize> = (0..links.len())
        .filter(|&k| links[k].parent < 0 || pos(links[k].parent).is_none())
        .collect();
    let Some(&root) = roots.first() else {
        return Err(malformed(
            &mob_path,
            "no root link (every link has a parent: a cycle)",
        ));
    };
    if roots.len() > 1 {
        notes.push(format!(
            "{} roots; extra roots merged into link id {}",
            roots.len(),
            links[root].id
        ));
    }
    let parent_of = |k: usize| -> Option<usize> {
        if k == root {
            None
        } else if roots.contains(&k) {
            Some(root)
        } else {
            pos(links[k].parent)
        }
    };

    // Build the unmerged object: parts = links with non-empty meshes (boxes = mesh AABB).
    let analytic_obj = match std::fs::read_to_string(dir.join("physnap_shapes.json")) {
        Ok(text) => Some(
            crate::io::object_json::from_str(&text)
                .map_err(|e| malformed(&dir.join("physnap_shapes.json"), e.to_string()))?,
        ),
        Err(_) => None,
    };
    let analytic = analytic_obj
        .as_ref()
        .is_some_and(|a| a.parts.len() == links.len());
    let mut parts = Vec::with_capacity(links.len());
    for (k, l) in links.iter().enumerate() {
        let part = if analytic {
            let mut p = analytic_obj
                .as_ref()
                .map(|a| a.parts[k].clone())
                .ok_or_else(|| malformed(dir, "shapes"))?;
            p.name = format!("link_{}", l.id);
            p
        } else {
            let Some((lo, hi)) = l.mesh.bounds() else {
                return Err(malformed(
                    dir,
                    format!(
                        "link id {} has no geometry (all meshes missing or empty)",
                        l.id
                    ),
                ));
            };
            let lo = Vector3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64);
            let hi = Vector3::new(hi[0] as f64, hi[1] as f64, hi[2] as f64);
            Part {
                name: format!("link_{}", l.id),
                half_extents: ((hi - lo) / 2.0).map(|v| v.max(1e-5)),
                center: (hi + lo) / 2.0,
                shape: PartShape::Box,
            }
        };
        parts.push(part);
    }
    let mut joints = Vec::new();
    for k in 0..links.len() {
        let Some(p) = parent_of(k) else { continue };
        let l = &links[k];
        let (axis, origin) = l
            .axis
            .unwrap_or((Vector3::z(), Point3::from(parts[k].center)));
        joints.push(Joint {
            parent: p,
            child: k,
            kind: l.kind,
            axis,
            origin,
            revolute: l.revolute,
            prismatic: l.prismatic,
        });
    }
    let full = ArticulatedObject {
        name: format!("pm_{id}"),
        category: Some(category.clone()),
        parts,
        joints,
    };
    // Validate the link tree before merging (so > 8 links with fixed children still import).
    validate_loose(&full).map_err(|e| malformed(dir, e.to_string()))?;
    let (object, map) = merge_fixed_loose(&full).map_err(|e| malformed(dir, e.to_string()))?;
    let n = object.parts.len();
    if !(2..=MAX_PARTS).contains(&n) {
        return Err(malformed(
            dir,
            format!("{n} nodes after merging fixed joints (must be between 2 and {MAX_PARTS})"),
        ));
    }
    let mut meshes = vec![TriMesh::default(); n];
    let mut labels = vec![String::new(); n];
    for (k, l) in links.iter().enumerate() {
        let m = &mut meshes[map[k]];
        let base = m.positions.len() as u32;
        m.positions.extend_from_slice(&l.mesh.positions);
        m.triangles.extend(
            l.mesh
                .triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
        if labels[map[k]].is_empty() || parent_of(k).is_none_or(|p| map[p] != map[k]) {
            labels[map[k]] = l.label.clone();
        }
    }
    Ok(ImportedObject {
        id,
        category,
        object,
        labels,
        meshes,
        analytic,
        notes,
    })
}

/// Tree checks that do not require ≤ 8 parts (raw PM objects may have more links).
fn validate_loose(obj: &ArticulatedObject) -> Result<(), CoreError> {
    if obj.parts.len() <= MAX_PARTS {
        return obj.validate();
    }
    let n = obj.parts.len();
    let mut parent = vec![None; n];
    for j in &obj.joints {
        if parent[j.child].replace(j.parent).is_some() {
            return Err(CoreError::Structure(format!(
                "link {} has two parents",
                obj.parts[j.child].name
            )));
        }
    }
    for s in 0..n {
        let (mut cur, mut steps) = (s, 0);
        while let Some(p) = parent[cur] {
            cur = p;
            steps += 1;
            if steps > n {
                return Err(CoreError::Structure("link parents form a cycle".into()));
            }
        }
    }
    Ok(())
}

/// [`ArticulatedObject::merge_fixed`] for link trees that may exceed 8 parts before merging.
fn merge_fixed_loose(
    obj: &ArticulatedObject,
) -> Result<(ArticulatedObject, Vec<usize>), CoreError> {
    if obj.parts.len() <= MAX_PARTS {
        return obj.merge_fixed();
    }
    let movable = obj
        .joints
        .iter()
        .filter(|j| j.kind != JointKind::Fixed)
        .count();
    Err(CoreError::Structure(format!(
        "{} links, {} nodes after merging fixed joints (must be between 2 and {MAX_PARTS})",
        obj.parts.len(),
        movable + 1
    )))
}
