//! URDF export: `robot.urdf` plus `meshes/<link>.obj`.
//!
//! Why it exists: URDF is what simulators (PyBullet, SAPIEN, MuJoCo via conversion, Isaac)
//! load. Layout:
//!
//! - one `<link>` per part, with visual + collision mesh and a box inertial (density ×
//!   box volume, solid-box inertia about the box centre);
//! - link frames: the root link's frame is the object frame; every other link's frame sits
//!   at its joint origin (a point on the joint axis, object frame at rest), axes parallel to the
//!   object frame. Mesh files are written in their link's frame, so `<visual><origin>` is zero;
//! - joint `<origin xyz>` = child frame − parent frame; `<axis>` = the unit joint axis;
//!   `<limit>` always carries `effort` and `velocity` (urdf-rs and many loaders require them);
//! - a screw joint becomes `prismatic` parent → `<child>_screw_helper` and `revolute`
//!   helper → child, both about the same axis (PartNet-Mobility's convention, data.md §A.3).
//!
//! Numbers use Rust's shortest round-trip formatting, so the file re-reads bit-exactly.

use std::fmt::Write;

use nalgebra::Vector3;

use super::ExportOptions;
use super::names::safe_unique;
use crate::mesh::TriMesh;
use crate::object::{ArticulatedObject, JointKind};

/// Colours used for parts (linear RGB), cycled by part index; shared with the GLB writer.
pub const PALETTE: [[f32; 3]; 8] = [
    [0.80, 0.80, 0.78],
    [0.85, 0.33, 0.10],
    [0.00, 0.45, 0.74],
    [0.47, 0.67, 0.19],
    [0.93, 0.69, 0.13],
    [0.49, 0.18, 0.56],
    [0.30, 0.75, 0.93],
    [0.64, 0.08, 0.18],
];

/// A URDF document and its mesh files (file name → OBJ text), sorted by name.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfBundle {
    /// `robot.urdf` contents.
    pub urdf: String,
    /// `(file name, contents)` for `meshes/<file name>`.
    pub meshes: Vec<(String, String)>,
}

/// Where each link's frame sits in the object frame at rest.
pub fn link_frames(obj: &ArticulatedObject) -> Vec<Vector3<f64>> {
    (0..obj.parts.len())
        .map(|p| match obj.parent_joint(p) {
            Some(k) => obj.joints[k].origin.coords,
            None => Vector3::zeros(),
        })
        .collect()
}

fn v(a: &Vector3<f64>) -> String {
    format!("{} {} {}", a.x, a.y, a.z)
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Build the URDF and its OBJ meshes. `meshes[p]` is part p's mesh in the object frame at rest.
pub fn build(obj: &ArticulatedObject, meshes: &[TriMesh], opts: &ExportOptions) -> UrdfBundle {
    let names = safe_unique(&obj.parts.iter().map(|p| p.name.clone()).collect::<Vec<_>>());
    let frames = link_frames(obj);
    let robot = safe_unique(std::slice::from_ref(&obj.name)).remove(0);
    let mut x = String::new();
    // Writing into a String cannot fail; the `let _ =` below discard Ok(()).
    let _ = writeln!(x, "<?xml version=\"1.0\"?>");
    let _ = writeln!(x, "<robot name=\"{}\">", xml_escape(&robot));
    let mut mesh_files = Vec::new();
    for (p, part) in obj.parts.iter().enumerate() {
        let name = &names[p];
        let [r, g, b] = PALETTE[p % PALETTE.len()];
        let com = part.center - frames[p];
        let h = part.half_extents;
        let mass = opts.density * part.volume();
        let (sx, sy, sz) = (
            (2.0 * h.x).powi(2),
            (2.0 * h.y).powi(2),
            (2.0 * h.z).powi(2),
        );
        let _ = writeln!(x, "  <link name=\"{name}\">");
        let _ = writeln!(x, "    <inertial>");
        let _ = writeln!(x, "      <origin xyz=\"{}\" rpy=\"0 0 0\"/>", v(&com));
        let _ = writeln!(x, "      <mass value=\"{mass}\"/>");
        let _ = writeln!(
            x,
            "      <inertia ixx=\"{}\" ixy=\"0\" ixz=\"0\" iyy=\"{}\" iyz=\"0\" izz=\"{}\"/>",
            mass * (sy + sz) / 12.0,
            mass * (sx + sz) / 12.0,
            mass * (sx + sy) / 12.0
        );
        let _ = writeln!(x, "    </inertial>");
        if !meshes[p].is_empty() {
            let file = format!("{name}.obj");
            for tag in ["visual", "collision"] {
                let _ = writeln!(x, "    <{tag}>");
                let _ = writeln!(x, "      <origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>");
                let _ = writeln!(
                    x,
                    "      <geometry><mesh filename=\"meshes/{file}\"/></geometry>"
                );
                if tag == "visual" {
                    let _ = writeln!(
                        x,
                        "      <material name=\"{name}_color\"><color rgba=\"{r} {g} {b} 1\"/></material>"
                    );
                }
                let _ = writeln!(x, "    </{tag}>");
            }
            mesh_files.push((file, obj_text(&meshes[p], &frames[p])));
        }
        let _ = writeln!(x, "  </link>");
    }
    for k in obj.joints_topological() {
        let j = &obj.joints[k];
        let (parent, child) = (&names[j.parent], &names[j.child]);
        let origin = frames[j.child] - frames[j.parent];
        let axis = v(&j.axis);
        let limit = |r: [f64; 2]| {
            format!(
                "<limit lower=\"{}\" upper=\"{}\" effort=\"{}\" velocity=\"{}\"/>",
                r[0], r[1], opts.effort, opts.velocity
            )
        };
        let mut joint = |name: &str,
                         ty: &str,
                         parent: &str,
                         child: &str,
                         origin: &Vector3<f64>,
                         limit: Option<String>| {
            let _ = writeln!(x, "  <joint name=\"{name}\" type=\"{ty}\">");
            let _ = writeln!(x, "    <parent link=\"{parent}\"/>");
            let _ = writeln!(x, "    <child link=\"{child}\"/>");
            let _ = writeln!(x, "    <origin xyz=\"{}\" rpy=\"0 0 0\"/>", v(origin));
            if let Some(limit) = limit {
                let _ = writeln!(x, "    <axis xyz=\"{axis}\"/>");
                let _ = writeln!(x, "    {limit}");
            }
            let _ = writeln!(x, "  </joint>");
        };
        match j.kind {
            JointKind::Fixed => joint(
                &format!("joint_{child}"),
                "fixed",
                parent,
                child,
                &origin,
                None,
            ),
            JointKind::Revolute => joint(
                &format!("joint_{child}"),
                "revolute",
                parent,
                child,
                &origin,
                Some(limit(j.revolute)),
            ),
            JointKind::Prismatic => joint(
                &format!("joint_{child}"),
                "prismatic",
                parent,
                child,
                &origin,
                Some(limit(j.prismatic)),
            ),
            JointKind::Screw => {
                let helper = format!("{child}_screw_helper");
                joint(
                    &format!("joint_{child}_slide"),
                    "prismatic",
                    parent,
                    &helper,
                    &origin,
                    Some(limit(j.prismatic)),
                );
                joint(
                    &format!("joint_{child}_turn"),
                    "revolute",
                    &helper,
                    child,
                    &Vector3::zeros(),
                    Some(limit(j.revolute)),
                );
                // A tiny inertial keeps simulators that reject massless links happy.
                let _ = writeln!(
                    x,
                    "  <link name=\"{helper}\"><inertial><mass value=\"0.001\"/><inertia ixx=\"1e-9\" ixy=\"0\" ixz=\"0\" iyy=\"1e-9\" iyz=\"0\" izz=\"1e-9\"/></inertial></link>"
                );
            }
        }
    }
    let _ = writeln!(x, "</robot>");
    mesh_files.sort();
    UrdfBundle {
        urdf: x,
        meshes: mesh_files,
    }
}

/// Wavefront OBJ text of `mesh` shifted by −`frame` (positions and per-vertex normals).
pub fn obj_text(mesh: &TriMesh, frame: &Vector3<f64>) -> String {
    let mut s = String::with_capacity(mesh.positions.len() * 60 + mesh.triangles.len() * 30);
    let _ = writeln!(s, "# physnap part mesh, metres, link frame");
    for p in &mesh.positions {
        let _ = writeln!(
            s,
            "v {} {} {}",
            p[0] as f64 - frame.x,
            p[1] as f64 - frame.y,
            p[2] as f64 - frame.z
        );
    }
    for n in mesh.vertex_normals() {
        let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
    }
    for t in &mesh.triangles {
        let (a, b, c) = (t[0] + 1, t[1] + 1, t[2] + 1);
        let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
    }
    s
}
