//! GLB export: the object as a glTF scene a viewer can animate.
//!
//! Why it exists: a GLB opens in any viewer and in the browser, so people can *see* a
//! generated object move. Mapping (the generic writer is [`super::gltf`]):
//!
//! - one node per part, holding its mesh in the part frame (vertices − box centre);
//! - one pivot node per joint, between the parent's part node and the child's: it sits at the
//!   joint origin, and rotating/translating the pivot about/along the joint axis is exactly the
//!   joint's screw motion, so the node hierarchy is the kinematic tree;
//! - joint type, axis, origin, limits, effort and velocity in the pivot node's `extras.joint`;
//!   part name and box in the part node's `extras.part`;
//! - one animation per movable joint, sweeping lower → upper → lower (linear keys; rotation keys
//!   at most 45° apart so interpolation follows the range);
//! - one material per part, colours from [`super::urdf::PALETTE`].
//!
//! Frames: physnap's object frame is metres, +Z up. glTF is +Y up, so every position and
//! direction is mapped (x, y, z) ↦ (x, z, −y), a −90° rotation about X. `extras` values are in
//! the glTF frame; the asset `extras.physnap.frame` states the mapping.

use nalgebra::{Unit, UnitQuaternion, Vector3};
use serde_json::json;

use super::gltf::{Animation, MeshData, Node, Scene, write_glb};
use super::names::safe_unique;
use super::urdf::PALETTE;
use super::{ExportError, ExportOptions};
use crate::mesh::TriMesh;
use crate::object::ArticulatedObject;

/// Object frame (+Z up) → glTF frame (+Y up).
pub fn to_gltf(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.x, v.z, -v.y)
}

fn f3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

fn quat(q: &UnitQuaternion<f64>) -> [f32; 4] {
    let c = q.coords;
    [c.x as f32, c.y as f32, c.z as f32, c.w as f32]
}

fn local_mesh(mesh: &TriMesh, center: &Vector3<f64>) -> MeshData {
    let positions: Vec<[f32; 3]> = mesh
        .positions
        .iter()
        .map(|p| {
            let v = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) - center;
            f3(&to_gltf(&v))
        })
        .collect();
    let normals = mesh
        .vertex_normals()
        .iter()
        .map(|n| {
            f3(&to_gltf(&Vector3::new(
                n[0] as f64,
                n[1] as f64,
                n[2] as f64,
            )))
        })
        .collect();
    MeshData {
        positions,
        normals,
        triangles: mesh.triangles.clone(),
    }
}

/// Build the GLB bytes. `meshes[p]` is part p's mesh in the object frame at rest.
pub fn build(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    opts: &ExportOptions,
) -> Result<Vec<u8>, ExportError> {
    let names = safe_unique(&obj.parts.iter().map(|p| p.name.clone()).collect::<Vec<_>>());
    let mut nodes: Vec<Node> = Vec::new();
    let mut part_node = vec![usize::MAX; obj.parts.len()];
    let mut animations = Vec::new();

    let part_extras = |p: usize| {
        let part = &obj.parts[p];
        let h = part.half_extents;
        json!({ "part": {
            "name": part.name,
            "index": p,
            "half_extents": f3(&Vector3::new(h.x, h.z, h.y)),
            "center": f3(&to_gltf(&part.center)),
        }})
    };
    let color = |p: usize| {
        let [r, g, b] = PALETTE[p % PALETTE.len()];
        [r, g, b, 1.0]
    };

    let root = obj.root();
    // The scan's frame (crate::frame): one root node holding canonical → scan in glTF axes,
    // A·T·A⁻¹ with A: (x, y, z) ↦ (x, z, −y).
    let frame_node = opts.frame.filter(|f| !f.is_canonical()).map(|f| {
        let iso = f.to_scan();
        let a = nalgebra::Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0);
        let r = a * iso.rotation.to_rotation_matrix().matrix() * a.transpose();
        let q =
            UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r));
        nodes.push(Node {
            name: "scan_frame".into(),
            parent: None,
            translation: f3(&to_gltf(&iso.translation.vector)),
            rotation: quat(&q),
            mesh: None,
            color: [1.0; 4],
            extras: json!({ "frame": {
                "up": f3(&f.up),
                "yaw": f.yaw,
                "translation": f3(&f.translation),
                "note": "canonical (physnap object frame) -> the scan's frame",
            }}),
        });
        nodes.len() - 1
    });
    part_node[root] = nodes.len();
    nodes.push(Node {
        name: names[root].clone(),
        parent: frame_node,
        translation: f3(&to_gltf(&obj.parts[root].center)),
        rotation: [0.0, 0.0, 0.0, 1.0],
        mesh: Some(local_mesh(&meshes[root], &obj.parts[root].center)),
        color: color(root),
        extras: part_extras(root),
    });

    for k in obj.joints_topological() {
        let j = &obj.joints[k];
        let (p, c) = (j.parent, j.child);
        let pivot_rest = to_gltf(&(j.origin.coords - obj.parts[p].center));
        let axis = to_gltf(&j.axis);
        let pivot = nodes.len();
        nodes.push(Node {
            name: format!("joint_{}", names[c]),
            parent: Some(part_node[p]),
            translation: f3(&pivot_rest),
            rotation: [0.0, 0.0, 0.0, 1.0],
            mesh: None,
            color: [1.0; 4],
            extras: json!({ "joint": {
                "type": j.kind.as_str(),
                "parent": obj.parts[p].name,
                "child": obj.parts[c].name,
                "axis": f3(&axis),
                "origin": f3(&to_gltf(&j.origin.coords)),
                "limits": {
                    "revolute": j.kind.rotates().then_some(j.revolute),
                    "prismatic": j.kind.slides().then_some(j.prismatic),
                },
                "effort": opts.effort,
                "velocity": opts.velocity,
            }}),
        });
        part_node[c] = nodes.len();
        nodes.push(Node {
            name: names[c].clone(),
            parent: Some(pivot),
            translation: f3(&to_gltf(&(obj.parts[c].center - j.origin.coords))),
            rotation: [0.0, 0.0, 0.0, 1.0],
            mesh: Some(local_mesh(&meshes[c], &obj.parts[c].center)),
            color: color(c),
            extras: part_extras(c),
        });
        if let Some(anim) = sweep(j, pivot, &pivot_rest, &axis, &names[c], opts.sweep_seconds) {
            animations.push(anim);
        }
    }

    let scene = Scene {
        nodes,
        animations,
        extras: json!({ "physnap": {
            "name": obj.name,
            "category": obj.category,
            "units": "metres",
            "frame": "glTF +Y up; physnap object frame is +Z up, mapped (x, y, z) -> (x, z, -y)",
        }}),
    };
    Ok(write_glb(&scene)?)
}

/// Keyframes sweeping joint `j` lower → upper → lower; `None` for a fixed joint.
fn sweep(
    j: &crate::object::Joint,
    pivot: usize,
    pivot_rest: &Vector3<f64>,
    axis: &Vector3<f64>,
    child_name: &str,
    seconds: f32,
) -> Option<Animation> {
    use crate::object::JointKind;
    if j.kind == JointKind::Fixed {
        return None;
    }
    let width = (j.revolute[1] - j.revolute[0]).abs();
    // Keys at most 45° apart, so slerp between neighbours never takes the short way round.
    let per_leg = ((width / std::f64::consts::FRAC_PI_4).ceil() as usize).clamp(16, 512);
    let total = 2 * per_leg;
    let unit_axis = Unit::new_normalize(*axis);
    let mut times = Vec::with_capacity(total + 1);
    let mut rotations = Vec::new();
    let mut translations = Vec::new();
    for s in 0..=total {
        let f = if s <= per_leg {
            s as f64 / per_leg as f64
        } else {
            (total - s) as f64 / per_leg as f64
        };
        times.push(seconds * s as f32 / per_leg as f32);
        let q = j.state_at(f);
        if j.kind.rotates() {
            rotations.push(quat(&UnitQuaternion::from_axis_angle(&unit_axis, q.angle)));
        }
        if j.kind.slides() {
            translations.push(f3(&(pivot_rest + axis * q.displacement)));
        }
    }
    Some(Animation {
        name: format!("joint_{child_name}"),
        node: pivot,
        times,
        translations,
        rotations,
    })
}
