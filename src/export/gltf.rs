//! Binary glTF 2.0 (GLB) writer.
//!
//! # Why this exists
//!
//! The GLB file is one of the two artefacts a user takes home from physnap: it carries the
//! generated articulated object (one node per part, the kinematic tree as the node hierarchy,
//! joint motion as animations) in a form any glTF viewer or engine opens directly. The
//! higher-level exporter maps parts and joints onto the small, generic [`Scene`] type below and
//! calls [`write_glb`]; this module knows nothing about articulation, only about glTF.
//!
//! # File layout
//!
//! ```text
//! header  : magic "glTF" | version 2 | total length          (3 x u32 little-endian)
//! chunk 0 : length | "JSON" | glTF JSON, padded with spaces (0x20) to a multiple of 4
//! chunk 1 : length | "BIN\0" | binary buffer, padded with zeros to a multiple of 4
//! ```
//!
//! The BIN chunk (omitted when the scene has no binary data) is the single buffer `buffers[0]`.
//! It is filled in a fixed order, one bufferView per accessor, each starting on a 4-byte boundary
//! (every element is an `f32` or `u32`, so views are tightly packed and `byteStride` is omitted):
//!
//! 1. for every node with a non-empty mesh, in node order: POSITION (`VEC3` float, exact
//!    `min`/`max`, target `ARRAY_BUFFER`), NORMAL when present (`VEC3` float, `ARRAY_BUFFER`),
//!    indices (`SCALAR` `UNSIGNED_INT`, target `ELEMENT_ARRAY_BUFFER`);
//! 2. for every animation, in order: key times (`SCALAR` float with `min`/`max`, no target), then
//!    translation outputs (`VEC3`) and rotation outputs (`VEC4`) when present.
//!
//! Only objects that are referenced are written (no unused accessors, views or materials), JSON
//! objects are serialised in a fixed key order, and no timestamps or hash-map iteration are
//! involved, so the same [`Scene`] always yields byte-identical output.
//!
//! # Validation
//!
//! [`write_glb`] checks the scene before writing anything and reports the first problem as a
//! [`GltfError::InvalidScene`] naming the offending field (e.g. `nodes[3].parent`):
//!
//! * parent indices in range and the parent relation acyclic;
//! * every float finite; colours in `[0, 1]`;
//! * normals either empty or one per position, each of unit length within 1e-3;
//! * triangle indices below the vertex count;
//! * quaternions (node rotations and animation keys) of unit length within 1e-3;
//! * animations: target node in range, times non-negative and strictly increasing, output
//!   lengths equal to the number of times, at least one of translations / rotations.
//!
//! Near-unit normals and quaternions are renormalised before they are written, since the glTF
//! validator rejects vectors that are not unit length to within float precision. Meshes with no
//! vertices or no triangles are dropped (the node gets no `mesh`), since glTF forbids empty
//! accessors. The output is checked against the Khronos glTF-Validator in the tests
//! (`tests/tools/validate_gltf.js`): zero errors and zero warnings.

use std::fmt;

use serde_json::{Map, Value, json};

/// One triangle mesh, already in glTF coordinates (+Y up, metres), local to its node.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MeshData {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals, same length as positions (may be empty: then no NORMAL attribute).
    pub normals: Vec<[f32; 3]>,
    /// Counter-clockwise triangles (front face outward).
    pub triangles: Vec<[u32; 3]>,
}

/// One scene node.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Node name (written as glTF `name`).
    pub name: String,
    /// Index into Scene::nodes of the parent, None for a root node. Parents may come after children in the vec.
    pub parent: Option<usize>,
    /// Local rest translation.
    pub translation: [f32; 3],
    /// Local rest rotation, unit quaternion [x, y, z, w].
    pub rotation: [f32; 4],
    /// Optional geometry, local to this node.
    pub mesh: Option<MeshData>,
    /// Base colour RGBA in linear space, used for this node's mesh material (one material per meshed node).
    pub color: [f32; 4],
    /// Written verbatim as the node's `extras` (skip if Null).
    pub extras: Value,
}

/// One animation: keyframes for one node (linear interpolation).
#[derive(Debug, Clone, PartialEq)]
pub struct Animation {
    /// Animation name (written as glTF `name`).
    pub name: String,
    /// Index into Scene::nodes of the animated node.
    pub node: usize,
    /// Strictly increasing times in seconds.
    pub times: Vec<f32>,
    /// Either empty or one per time.
    pub translations: Vec<[f32; 3]>,
    /// Either empty or one unit quaternion [x, y, z, w] per time.
    pub rotations: Vec<[f32; 4]>,
}

/// Everything that goes into one GLB file.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// All nodes; roots are those with `parent == None`.
    pub nodes: Vec<Node>,
    /// Animations, one glTF animation each.
    pub animations: Vec<Animation>,
    /// Written as the asset-level `extras` (e.g. the coordinate convention), skip if Null.
    pub extras: Value,
}

/// Errors from [`write_glb`] and [`read_glb_json`].
#[derive(Debug)]
pub enum GltfError {
    /// The scene breaks an invariant; `field` names the offending value, e.g.
    /// `nodes[2].mesh.triangles[7]`.
    InvalidScene {
        /// Path of the offending field.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The scene does not fit the 32-bit sizes of the GLB container.
    TooLarge {
        /// What overflowed.
        what: String,
    },
    /// The bytes given to [`read_glb_json`] are not a well-formed GLB.
    InvalidGlb {
        /// What is wrong with them.
        reason: String,
    },
    /// The JSON chunk could not be serialised or parsed.
    Json(serde_json::Error),
}

impl fmt::Display for GltfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::InvalidScene { field, reason } => write!(f, "invalid scene: {field}: {reason}"),
            Self::TooLarge { what } => write!(f, "scene too large for GLB: {what}"),
            Self::InvalidGlb { reason } => write!(f, "invalid GLB: {reason}"),
            Self::Json(e) => write!(f, "glTF JSON error: {e}"),
        }
    }
}

impl std::error::Error for GltfError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Json(e) => Some(e),
            _ => None,
        }
    }
}

impl From<serde_json::Error> for GltfError {
    fn from(e: serde_json::Error) -> Self {
        Self::Json(e)
    }
}

/// `metallicFactor` of every material.
pub const METALLIC_FACTOR: f32 = 0.0;
/// `roughnessFactor` of every material.
pub const ROUGHNESS_FACTOR: f32 = 0.8;
/// Allowed deviation from 1 of the length of quaternions and normals.
pub const UNIT_TOLERANCE: f64 = 1e-3;

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const GLB_VERSION: u32 = 2;
const GLB_HEADER_LEN: usize = 12;
const CHUNK_HEADER_LEN: usize = 8;
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"

const COMPONENT_FLOAT: u32 = 5126;
const COMPONENT_UNSIGNED_INT: u32 = 5125;
const TARGET_ARRAY_BUFFER: u32 = 34962;
const TARGET_ELEMENT_ARRAY_BUFFER: u32 = 34963;
const MODE_TRIANGLES: u32 = 4;

/// Serialise to GLB bytes. Validates the scene first (parent indices in range, no cycles, indices < vertex count,
/// finite values, normals length == positions length when non-empty, unit quaternions within 1e-3 (renormalise
/// them before writing), animation times strictly increasing and output lengths matching) and returns a clear error otherwise.
pub fn write_glb(scene: &Scene) -> Result<Vec<u8>, GltfError> {
    validate(scene)?;
    let (root, mut bin) = build_json(scene);
    let mut json_bytes = serde_json::to_vec(&root)?;
    pad_to_4(&mut json_bytes, b' ');
    pad_to_4(&mut bin, 0);

    let bin_chunk_len = if bin.is_empty() {
        0
    } else {
        CHUNK_HEADER_LEN + bin.len()
    };
    let total = GLB_HEADER_LEN + CHUNK_HEADER_LEN + json_bytes.len() + bin_chunk_len;
    let total_u32 = to_u32(total, "total file length")?;

    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(&GLB_MAGIC.to_le_bytes());
    out.extend_from_slice(&GLB_VERSION.to_le_bytes());
    out.extend_from_slice(&total_u32.to_le_bytes());
    out.extend_from_slice(&to_u32(json_bytes.len(), "JSON chunk length")?.to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&json_bytes);
    if !bin.is_empty() {
        out.extend_from_slice(&to_u32(bin.len(), "BIN chunk length")?.to_le_bytes());
        out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        out.extend_from_slice(&bin);
    }
    debug_assert_eq!(out.len(), total);
    Ok(out)
}

/// Parse the GLB header and return the JSON chunk as a [`Value`] (the BIN chunk is ignored).
pub fn read_glb_json(bytes: &[u8]) -> Result<Value, GltfError> {
    let bad = |reason: String| GltfError::InvalidGlb { reason };
    let word = |offset: usize| -> Result<u32, GltfError> {
        bytes
            .get(offset..offset + 4)
            .and_then(|b| <[u8; 4]>::try_from(b).ok())
            .map(u32::from_le_bytes)
            .ok_or_else(|| {
                bad(format!(
                    "truncated: {} bytes, need at least {}",
                    bytes.len(),
                    offset + 4
                ))
            })
    };
    let magic = word(0)?;
    if magic != GLB_MAGIC {
        return Err(bad(format!(
            "bad magic 0x{magic:08x}, expected 0x{GLB_MAGIC:08x} (\"glTF\")"
        )));
    }
    let version = word(4)?;
    if version != GLB_VERSION {
        return Err(bad(format!("unsupported GLB version {version}")));
    }
    let declared = word(8)? as usize;
    if declared > bytes.len() {
        return Err(bad(format!(
            "header declares {declared} bytes but only {} are present",
            bytes.len()
        )));
    }
    let json_len = word(12)? as usize;
    let chunk_type = word(16)?;
    if chunk_type != CHUNK_JSON {
        return Err(bad(format!(
            "first chunk has type 0x{chunk_type:08x}, expected JSON (0x{CHUNK_JSON:08x})"
        )));
    }
    let start = GLB_HEADER_LEN + CHUNK_HEADER_LEN;
    let end = start
        .checked_add(json_len)
        .filter(|&end| end <= declared)
        .ok_or_else(|| {
            bad(format!(
                "JSON chunk of {json_len} bytes overruns the declared length {declared}"
            ))
        })?;
    Ok(serde_json::from_slice(&bytes[start..end])?)
}

// ---------------------------------------------------------------------------------------------
// Validation

fn invalid(field: impl Into<String>, reason: impl Into<String>) -> GltfError {
    GltfError::InvalidScene {
        field: field.into(),
        reason: reason.into(),
    }
}

fn check_finite(field: &str, values: &[f32]) -> Result<(), GltfError> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(v) => Err(invalid(
            field,
            format!("non-finite value {v} in {values:?}"),
        )),
        None => Ok(()),
    }
}

fn norm(v: &[f32]) -> f64 {
    v.iter()
        .map(|&x| f64::from(x) * f64::from(x))
        .sum::<f64>()
        .sqrt()
}

/// Finite and of unit length within [`UNIT_TOLERANCE`].
fn check_unit(field: &str, what: &str, v: &[f32]) -> Result<(), GltfError> {
    check_finite(field, v)?;
    let n = norm(v);
    if (n - 1.0).abs() > UNIT_TOLERANCE {
        return Err(invalid(
            field,
            format!("{what} {v:?} has length {n}, expected 1 (tolerance {UNIT_TOLERANCE})"),
        ));
    }
    Ok(())
}

fn validate(scene: &Scene) -> Result<(), GltfError> {
    let n = scene.nodes.len();
    for (i, node) in scene.nodes.iter().enumerate() {
        validate_node(i, node, n)?;
    }
    check_acyclic(&scene.nodes)?;
    for (k, anim) in scene.animations.iter().enumerate() {
        validate_animation(k, anim, n)?;
    }
    Ok(())
}

fn validate_node(i: usize, node: &Node, node_count: usize) -> Result<(), GltfError> {
    let f = |name: &str| format!("nodes[{i}].{name}");
    if let Some(p) = node.parent {
        if p >= node_count {
            return Err(invalid(
                f("parent"),
                format!("parent index {p} out of range (scene has {node_count} nodes)"),
            ));
        }
        if p == i {
            return Err(invalid(f("parent"), "node is its own parent"));
        }
    }
    check_finite(&f("translation"), &node.translation)?;
    check_unit(&f("rotation"), "quaternion", &node.rotation)?;
    check_finite(&f("color"), &node.color)?;
    if let Some(c) = node.color.iter().find(|c| !(0.0..=1.0).contains(*c)) {
        return Err(invalid(
            f("color"),
            format!("component {c} outside [0, 1] in {:?}", node.color),
        ));
    }
    let Some(mesh) = &node.mesh else {
        return Ok(());
    };
    for (j, p) in mesh.positions.iter().enumerate() {
        check_finite(&f(&format!("mesh.positions[{j}]")), p)?;
    }
    if !mesh.normals.is_empty() {
        if mesh.normals.len() != mesh.positions.len() {
            return Err(invalid(
                f("mesh.normals"),
                format!(
                    "{} normals for {} positions (must be equal, or no normals)",
                    mesh.normals.len(),
                    mesh.positions.len()
                ),
            ));
        }
        for (j, nrm) in mesh.normals.iter().enumerate() {
            check_unit(&f(&format!("mesh.normals[{j}]")), "normal", nrm)?;
        }
    }
    let vertex_count = mesh.positions.len();
    for (j, tri) in mesh.triangles.iter().enumerate() {
        if let Some(&v) = tri.iter().find(|&&v| v as usize >= vertex_count) {
            return Err(invalid(
                f(&format!("mesh.triangles[{j}]")),
                format!("vertex index {v} out of range ({vertex_count} vertices) in {tri:?}"),
            ));
        }
    }
    Ok(())
}

/// Every parent chain must end at a root. Parent indices are already known to be in range.
fn check_acyclic(nodes: &[Node]) -> Result<(), GltfError> {
    const UNSEEN: u8 = 0;
    const ON_PATH: u8 = 1;
    const DONE: u8 = 2;
    let mut state = vec![UNSEEN; nodes.len()];
    let mut path = Vec::new();
    for start in 0..nodes.len() {
        path.clear();
        let mut cur = Some(start);
        while let Some(i) = cur {
            match state[i] {
                DONE => break,
                ON_PATH => {
                    let pos = path.iter().position(|&p| p == i).unwrap_or(0);
                    let cycle: Vec<String> = path[pos..]
                        .iter()
                        .chain(std::iter::once(&i))
                        .map(|p: &usize| p.to_string())
                        .collect();
                    return Err(invalid(
                        format!("nodes[{i}].parent"),
                        format!("parent chain forms a cycle: {}", cycle.join(" -> ")),
                    ));
                }
                _ => {
                    state[i] = ON_PATH;
                    path.push(i);
                    cur = nodes[i].parent;
                }
            }
        }
        for &i in &path {
            state[i] = DONE;
        }
    }
    Ok(())
}

fn validate_animation(k: usize, anim: &Animation, node_count: usize) -> Result<(), GltfError> {
    let f = |name: &str| format!("animations[{k}].{name}");
    if anim.node >= node_count {
        return Err(invalid(
            f("node"),
            format!(
                "node index {} out of range (scene has {node_count} nodes)",
                anim.node
            ),
        ));
    }
    if anim.times.is_empty() {
        return Err(invalid(f("times"), "no keyframe times"));
    }
    let mut prev: Option<f32> = None;
    for (j, &t) in anim.times.iter().enumerate() {
        let field = f(&format!("times[{j}]"));
        if !t.is_finite() {
            return Err(invalid(field, format!("non-finite time {t}")));
        }
        if t < 0.0 {
            return Err(invalid(field, format!("negative time {t}")));
        }
        if let Some(p) = prev
            && t <= p
        {
            return Err(invalid(
                field,
                format!("times must be strictly increasing, but {t} follows {p}"),
            ));
        }
        prev = Some(t);
    }
    if anim.translations.is_empty() && anim.rotations.is_empty() {
        return Err(invalid(
            format!("animations[{k}]"),
            "neither translations nor rotations given (nothing to animate)",
        ));
    }
    let check_len = |name: &str, len: usize| {
        if len != 0 && len != anim.times.len() {
            return Err(invalid(
                f(name),
                format!(
                    "{len} keyframes for {} times (must be equal, or empty)",
                    anim.times.len()
                ),
            ));
        }
        Ok(())
    };
    check_len("translations", anim.translations.len())?;
    check_len("rotations", anim.rotations.len())?;
    for (j, t) in anim.translations.iter().enumerate() {
        check_finite(&f(&format!("translations[{j}]")), t)?;
    }
    for (j, q) in anim.rotations.iter().enumerate() {
        check_unit(&f(&format!("rotations[{j}]")), "quaternion", q)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Writing

fn to_u32(n: usize, what: &str) -> Result<u32, GltfError> {
    u32::try_from(n).map_err(|_| GltfError::TooLarge {
        what: format!("{what} is {n} bytes, GLB allows at most {}", u32::MAX),
    })
}

fn pad_to_4(bytes: &mut Vec<u8>, fill: u8) {
    while !bytes.len().is_multiple_of(4) {
        bytes.push(fill);
    }
}

/// An `f32` as a JSON number holding exactly the same value (so `min`/`max` match the buffer).
fn num(x: f32) -> Value {
    Value::from(f64::from(x))
}

fn nums(xs: &[f32]) -> Value {
    Value::Array(xs.iter().copied().map(num).collect())
}

fn normalized<const N: usize>(v: [f32; N]) -> [f32; N] {
    let n = norm(&v);
    v.map(|x| (f64::from(x) / n) as f32)
}

fn mesh_is_empty(mesh: &MeshData) -> bool {
    mesh.positions.is_empty() || mesh.triangles.is_empty()
}

/// Accumulates the BIN chunk and the bufferViews / accessors that describe it.
#[derive(Default)]
struct BinBuilder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl BinBuilder {
    /// Append `data` as a new bufferView starting on a 4-byte boundary; returns its index.
    fn view(&mut self, data: &[u8], target: Option<u32>) -> usize {
        pad_to_4(&mut self.bin, 0);
        let mut view = Map::new();
        view.insert("buffer".into(), json!(0));
        view.insert("byteOffset".into(), json!(self.bin.len()));
        view.insert("byteLength".into(), json!(data.len()));
        if let Some(t) = target {
            view.insert("target".into(), json!(t));
        }
        self.bin.extend_from_slice(data);
        self.views.push(Value::Object(view));
        self.views.len() - 1
    }

    /// Float accessor over `items` (non-empty), in its own bufferView; returns its index.
    fn float_accessor<const N: usize>(
        &mut self,
        items: &[[f32; N]],
        target: Option<u32>,
        with_bounds: bool,
    ) -> usize {
        let data: Vec<u8> = items
            .iter()
            .flatten()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let view = self.view(&data, target);
        let ty = match N {
            1 => "SCALAR",
            2 => "VEC2",
            3 => "VEC3",
            _ => "VEC4",
        };
        let mut acc = Map::new();
        acc.insert("bufferView".into(), json!(view));
        acc.insert("componentType".into(), json!(COMPONENT_FLOAT));
        acc.insert("count".into(), json!(items.len()));
        acc.insert("type".into(), json!(ty));
        if with_bounds {
            let mut min = [f32::INFINITY; N];
            let mut max = [f32::NEG_INFINITY; N];
            for item in items {
                for c in 0..N {
                    min[c] = min[c].min(item[c]);
                    max[c] = max[c].max(item[c]);
                }
            }
            acc.insert("min".into(), nums(&min));
            acc.insert("max".into(), nums(&max));
        }
        self.accessors.push(Value::Object(acc));
        self.accessors.len() - 1
    }

    /// `UNSIGNED_INT` index accessor over the flattened triangles; returns its index.
    fn index_accessor(&mut self, triangles: &[[u32; 3]]) -> usize {
        let data: Vec<u8> = triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let view = self.view(&data, Some(TARGET_ELEMENT_ARRAY_BUFFER));
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": COMPONENT_UNSIGNED_INT,
            "count": triangles.len() * 3,
            "type": "SCALAR",
        }));
        self.accessors.len() - 1
    }
}

/// Build the glTF JSON document and the (unpadded) BIN chunk. The scene must be valid.
fn build_json(scene: &Scene) -> (Value, Vec<u8>) {
    let mut bin = BinBuilder::default();
    let mut meshes = Vec::new();
    let mut materials = Vec::new();
    let mut mesh_of_node: Vec<Option<usize>> = vec![None; scene.nodes.len()];

    for (i, node) in scene.nodes.iter().enumerate() {
        let Some(mesh) = node.mesh.as_ref().filter(|m| !mesh_is_empty(m)) else {
            continue;
        };
        let mut attributes = Map::new();
        let pos = bin.float_accessor(&mesh.positions, Some(TARGET_ARRAY_BUFFER), true);
        attributes.insert("POSITION".into(), json!(pos));
        if !mesh.normals.is_empty() {
            let normals: Vec<[f32; 3]> = mesh.normals.iter().map(|&n| normalized(n)).collect();
            let nrm = bin.float_accessor(&normals, Some(TARGET_ARRAY_BUFFER), false);
            attributes.insert("NORMAL".into(), json!(nrm));
        }
        let indices = bin.index_accessor(&mesh.triangles);

        materials.push(json!({
            "name": node.name,
            "pbrMetallicRoughness": {
                "baseColorFactor": nums(&node.color),
                "metallicFactor": num(METALLIC_FACTOR),
                "roughnessFactor": num(ROUGHNESS_FACTOR),
            },
            "doubleSided": false,
        }));
        meshes.push(json!({
            "name": node.name,
            "primitives": [{
                "attributes": attributes,
                "indices": indices,
                "material": materials.len() - 1,
                "mode": MODE_TRIANGLES,
            }],
        }));
        mesh_of_node[i] = Some(meshes.len() - 1);
    }

    let mut children: Vec<Vec<usize>> = vec![Vec::new(); scene.nodes.len()];
    let mut roots = Vec::new();
    for (i, node) in scene.nodes.iter().enumerate() {
        match node.parent {
            Some(p) => children[p].push(i),
            None => roots.push(i),
        }
    }

    let nodes: Vec<Value> = scene
        .nodes
        .iter()
        .enumerate()
        .map(|(i, node)| {
            let mut obj = Map::new();
            obj.insert("name".into(), json!(node.name));
            obj.insert("translation".into(), nums(&node.translation));
            obj.insert("rotation".into(), nums(&normalized(node.rotation)));
            if let Some(m) = mesh_of_node[i] {
                obj.insert("mesh".into(), json!(m));
            }
            if !children[i].is_empty() {
                obj.insert("children".into(), json!(children[i]));
            }
            if !node.extras.is_null() {
                obj.insert("extras".into(), node.extras.clone());
            }
            Value::Object(obj)
        })
        .collect();

    let animations: Vec<Value> = scene
        .animations
        .iter()
        .map(|anim| {
            let times: Vec<[f32; 1]> = anim.times.iter().map(|&t| [t]).collect();
            let input = bin.float_accessor(&times, None, true);
            let mut samplers = Vec::new();
            let mut channels = Vec::new();
            let mut add = |output: usize, path: &str| {
                samplers.push(json!({
                    "input": input,
                    "output": output,
                    "interpolation": "LINEAR",
                }));
                channels.push(json!({
                    "sampler": samplers.len() - 1,
                    "target": { "node": anim.node, "path": path },
                }));
            };
            if !anim.translations.is_empty() {
                add(
                    bin.float_accessor(&anim.translations, None, false),
                    "translation",
                );
            }
            if !anim.rotations.is_empty() {
                let rotations: Vec<[f32; 4]> =
                    anim.rotations.iter().map(|&q| normalized(q)).collect();
                add(bin.float_accessor(&rotations, None, false), "rotation");
            }
            json!({ "name": anim.name, "samplers": samplers, "channels": channels })
        })
        .collect();

    let mut asset = Map::new();
    asset.insert("version".into(), json!("2.0"));
    asset.insert(
        "generator".into(),
        json!(concat!("physnap ", env!("CARGO_PKG_VERSION"))),
    );
    if !scene.extras.is_null() {
        asset.insert("extras".into(), scene.extras.clone());
    }

    let mut root = Map::new();
    root.insert("asset".into(), Value::Object(asset));
    root.insert("scene".into(), json!(0));
    let scene_obj = if roots.is_empty() {
        json!({})
    } else {
        json!({ "nodes": roots })
    };
    root.insert("scenes".into(), json!([scene_obj]));
    // glTF forbids empty top-level arrays: only write the ones that have entries.
    let mut put = |key: &str, items: Vec<Value>| {
        if !items.is_empty() {
            root.insert(key.into(), Value::Array(items));
        }
    };
    put("nodes", nodes);
    put("meshes", meshes);
    put("materials", materials);
    put("animations", animations);
    put("accessors", bin.accessors);
    put("bufferViews", bin.views);
    if !bin.bin.is_empty() {
        root.insert("buffers".into(), json!([{ "byteLength": bin.bin.len() }]));
    }
    (Value::Object(root), bin.bin)
}

#[cfg(test)]
mod tests;
