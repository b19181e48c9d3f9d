//! URDF export: `robot.urdf` plus `meshes/<link>.obj` and `meshes/<link>_collision_<k>.obj`.
//!
//! Why it exists: URDF is what simulators (PyBullet, SAPIEN, MuJoCo, Isaac) load. Layout:
//!
//! - one `<link>` per part (names from [`super::names::link_names`]) with a `<visual>` mesh
//!   `meshes/<link>.obj`, one `<collision>` per collision piece `meshes/<link>_collision_<k>.obj`
//!   (k = 0, 1, … over the part's non-empty pieces; a part without pieces has no collision) and
//!   the `<inertial>` of [`super::inertial`] (origin = centre of mass in the link frame, the full
//!   tensor `ixx … izz` with its products);
//! - link frames: the root link's frame is the object frame; every other link's frame sits
//!   at its joint origin (a point on the joint axis, object frame at rest), axes parallel to the
//!   object frame. Mesh files are written in their link's frame, so every `<origin>` of a
//!   visual or collision is zero;
//! - joint `<origin xyz>` = child frame − parent frame; `<axis>` = the unit joint axis;
//!   `<limit>` always carries `effort` and `velocity` (urdf-rs and many loaders require them);
//!   every movable joint has `<dynamics damping friction>` ([`ExportOptions`]);
//! - a screw joint becomes `prismatic` parent → `<child>_screw_helper` and `revolute`
//!   helper → child, both about the same axis (PartNet-Mobility's convention, data.md §A.3);
//!   the helper link carries the floor inertial (`min_mass`, every moment m·t²/6).
//!
//! Numbers use Rust's shortest round-trip formatting, so the file re-reads bit-exactly.

use std::fmt::Write;

use nalgebra::{Matrix3, Vector3};

use super::ExportOptions;
use super::inertial::Inertial;
use super::names::{link_names, safe_unique};
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

/// A URDF document and its mesh files (file name → OBJ text), sorted by name. The MJCF
/// writer ([`super::mjcf`]) refers to the same files.
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

pub(crate) fn v(a: &Vector3<f64>) -> String {
    format!("{} {} {}", a.x, a.y, a.z)
}

pub(crate) fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// File name (under `meshes/`) of collision piece `k` of `link`.
pub fn collision_file(link: &str, k: usize) -> String {
    format!("{link}_collision_{k}.obj")
}

/// The non-empty collision pieces of a part, numbered as in their file names.
pub(crate) fn pieces(collision: &[TriMesh]) -> impl Iterator<Item = (usize, &TriMesh)> {
    collision.iter().filter(|m| !m.is_empty()).enumerate()
}

/// The inertial a screw joint's helper link carries: the floors of `opts`.
pub(crate) fn helper_inertial(opts: &ExportOptions) -> Inertial {
    let m = opts.inertial.min_mass;
    let t = opts.inertial.min_thickness;
    Inertial {
        mass: m,
        com: Vector3::zeros(),
        inertia: Matrix3::identity() * (m * t * t / 6.0),
    }
}

/// Build the URDF and its OBJ meshes. `meshes[p]` is part p's visual mesh, `collision[p]` its
/// convex collision pieces and `inertials[p]` its inertial, all in the object frame at rest;
/// one entry per part in each (panics otherwise; [`super::artefacts`] checks the lengths).
pub fn build(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    collision: &[Vec<TriMesh>],
    inertials: &[Inertial],
    opts: &ExportOptions,
) -> UrdfBundle {
    let names = link_names(obj);
    UrdfBundle {
        urdf: document(obj, &names, meshes, collision, inertials, opts),
        meshes: mesh_files(obj, &names, meshes, collision),
    }
}

/// The OBJ files of [`build`] (visual `<link>.obj` with normals, collision pieces without),
/// each in its link's frame, sorted by file name.
pub(crate) fn mesh_files(
    obj: &ArticulatedObject,
    names: &[String],
    meshes: &[TriMesh],
    collision: &[Vec<TriMesh>],
) -> Vec<(String, String)> {
    let frames = link_frames(obj);
    let mut files = Vec::new();
    for p in 0..obj.parts.len() {
        if !meshes[p].is_empty() {
            files.push((
                format!("{}.obj", names[p]),
                obj_text(&meshes[p], &frames[p]),
            ));
        }
        for (k, piece) in pieces(&collision[p]) {
            files.push((
                collision_file(&names[p], k),
                positions_obj_text(piece, &frames[p]),
            ));
        }
    }
    files.sort();
    files
}

/// `<inertial>` of `i` for a link whose frame sits at `frame`.
fn write_inertial(x: &mut String, indent: &str, i: &Inertial, frame: &Vector3<f64>) {
    let t = &i.inertia;
    let _ = writeln!(x, "{indent}<inertial>");
    let _ = writeln!(
        x,
        "{indent}  <origin xyz=\"{}\" rpy=\"0 0 0\"/>",
        v(&(i.com - frame))
    );
    let _ = writeln!(x, "{indent}  <mass value=\"{}\"/>", i.mass);
    let _ = writeln!(
        x,
        "{indent}  <inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/>",
        t[(0, 0)],
        t[(0, 1)],
        t[(0, 2)],
        t[(1, 1)],
        t[(1, 2)],
        t[(2, 2)]
    );
    let _ = writeln!(x, "{indent}</inertial>");
}

/// The link that stands for the scan's frame when the export has one ([`ExportOptions::frame`]).
pub const WORLD_LINK: &str = "world";

/// The URDF text of [`build`] with the link names given (one per part).
pub(crate) fn document(
    obj: &ArticulatedObject,
    names: &[String],
    meshes: &[TriMesh],
    collision: &[Vec<TriMesh>],
    inertials: &[Inertial],
    opts: &ExportOptions,
) -> String {
    let frames = link_frames(obj);
    let robot = safe_unique(std::slice::from_ref(&obj.name)).remove(0);
    let mut x = String::new();
    // Writing into a String cannot fail; the `let _ =` below discard Ok(()).
    let _ = writeln!(x, "<?xml version=\"1.0\"?>");
    let _ = writeln!(x, "<robot name=\"{}\">", xml_escape(&robot));
    for (p, name) in names.iter().enumerate() {
        let [r, g, b] = PALETTE[p % PALETTE.len()];
        let _ = writeln!(x, "  <link name=\"{name}\">");
        write_inertial(&mut x, "    ", &inertials[p], &frames[p]);
        if !meshes[p].is_empty() {
            let _ = writeln!(x, "    <visual>");
            let _ = writeln!(x, "      <origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>");
            let _ = writeln!(
                x,
                "      <geometry><mesh filename=\"meshes/{name}.obj\"/></geometry>"
            );
            let _ = writeln!(
                x,
                "      <material name=\"{name}_color\"><color rgba=\"{r} {g} {b} 1\"/></material>"
            );
            let _ = writeln!(x, "    </visual>");
        }
        for (k, _) in pieces(&collision[p]) {
            let _ = writeln!(x, "    <collision>");
            let _ = writeln!(x, "      <origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>");
            let _ = writeln!(
                x,
                "      <geometry><mesh filename=\"meshes/{}\"/></geometry>",
                collision_file(name, k)
            );
            let _ = writeln!(x, "    </collision>");
        }
        let _ = writeln!(x, "  </link>");
    }
    if let Some(f) = opts.frame.filter(|f| !f.is_canonical()) {
        // The scan's frame: `world` is the scan's origin, the root link sits where the scan
        // has it (crate::frame).
        let root = obj.root();
        let iso = f.to_scan() * nalgebra::Translation3::from(frames[root]);
        let (r, p, y) = iso.rotation.euler_angles();
        let _ = writeln!(x, "  <link name=\"{WORLD_LINK}\"/>");
        let _ = writeln!(
            x,
            "  <joint name=\"{WORLD_LINK}_to_{}\" type=\"fixed\">",
            names[root]
        );
        let _ = writeln!(x, "    <parent link=\"{WORLD_LINK}\"/>");
        let _ = writeln!(x, "    <child link=\"{}\"/>", names[root]);
        let _ = writeln!(
            x,
            "    <origin xyz=\"{}\" rpy=\"{}\"/>",
            v(&iso.translation.vector),
            v(&Vector3::new(r, p, y))
        );
        let _ = writeln!(x, "  </joint>");
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
                let _ = writeln!(
                    x,
                    "    <dynamics damping=\"{}\" friction=\"{}\"/>",
                    opts.damping, opts.friction
                );
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
                // Simulators reject massless links: the helper gets the floor inertial.
                let _ = writeln!(x, "  <link name=\"{helper}\">");
                write_inertial(&mut x, "    ", &helper_inertial(opts), &Vector3::zeros());
                let _ = writeln!(x, "  </link>");
            }
        }
    }
    let _ = writeln!(x, "</robot>");
    x
}

/// Wavefront OBJ text of `mesh` shifted by −`frame` (positions and per-vertex normals).
pub fn obj_text(mesh: &TriMesh, frame: &Vector3<f64>) -> String {
    obj_with(mesh, frame, true)
}

/// Wavefront OBJ text of `mesh` shifted by −`frame`, positions and faces only (collision
/// pieces: engines read no normals from them).
pub fn positions_obj_text(mesh: &TriMesh, frame: &Vector3<f64>) -> String {
    obj_with(mesh, frame, false)
}

fn obj_with(mesh: &TriMesh, frame: &Vector3<f64>, normals: bool) -> String {
    let mut s = String::with_capacity(mesh.positions.len() * 60 + mesh.triangles.len() * 30);
    let what = if normals {
        "part mesh"
    } else {
        "collision piece"
    };
    let _ = writeln!(s, "# physnap {what}, metres, link frame");
    for p in &mesh.positions {
        let _ = writeln!(
            s,
            "v {} {} {}",
            p[0] as f64 - frame.x,
            p[1] as f64 - frame.y,
            p[2] as f64 - frame.z
        );
    }
    if normals {
        for n in mesh.vertex_normals() {
            let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
        }
    }
    for t in &mesh.triangles {
        let (a, b, c) = (t[0] + 1, t[1] + 1, t[2] + 1);
        if normals {
            let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
        } else {
            let _ = writeln!(s, "f {a} {b} {c}");
        }
    }
    s
}
