//! MJCF export: `model.xml`, MuJoCo's native format, next to `robot.urdf`.
//!
//! Why it exists: MuJoCo's URDF importer drops visual geoms by default, has no geom groups and
//! finds meshes only through an injected `<mujoco><compiler>` element (scripts/sim_check.py);
//! a native MJCF file opens in MuJoCo's viewer and in `mujoco.MjModel.from_xml_path` as it is.
//! It describes the same model as [`super::urdf`], so a simulation of either agrees:
//!
//! - one `<body>` per part with the URDF link's name, nested as the kinematic tree; the root
//!   body is fixed to the world (no joint), like the URDF's root link. A body's frame is its
//!   link frame ([`super::urdf::link_frames`]): `pos` = child frame − parent frame, no rotation;
//! - joints at the body origin (`pos="0 0 0"`) with the URDF's names: `hinge` for revolute,
//!   `slide` for prismatic, and for a screw joint `joint_<child>_slide` + `joint_<child>_turn`
//!   in the same body about the same axis (the URDF needs a `<child>_screw_helper` link for
//!   that; MJCF does not, and a slide and a turn about one axis commute). Each has `range`,
//!   `damping`, `frictionloss` (URDF `friction`) and `actuatorfrcrange` ± effort (what MuJoCo's
//!   URDF importer makes of `effort`);
//! - `<inertial pos mass fullinertia>` from [`super::inertial`], centre of mass in the body
//!   frame, so MuJoCo never infers mass from geoms;
//! - a visual geom per part (`group="1" contype="0" conaffinity="0"`, mesh `<link>.obj`, the
//!   palette colour) and a collision geom per piece (`group="3"`, mesh
//!   `<link>_collision_<k>.obj`), from the same `meshes/` folder as the URDF
//!   (`<compiler meshdir="meshes">`), so the OBJ files are shared, not duplicated. MuJoCo
//!   re-centres each mesh at its own inertial frame internally; that moves no body.
//!
//! Written with `std::fmt::Write`, numbers in shortest round-trip form, like the URDF.

use std::fmt::Write;

use nalgebra::Vector3;

use super::ExportOptions;
use super::inertial::Inertial;
use super::names::{link_names, safe_unique};
use super::urdf::{PALETTE, collision_file, link_frames, mesh_files, pieces, v, xml_escape};
use crate::mesh::TriMesh;
use crate::object::{ArticulatedObject, JointKind};

/// An MJCF document and its mesh files (the same files as [`super::urdf::UrdfBundle`]).
#[derive(Debug, Clone, PartialEq)]
pub struct MjcfBundle {
    /// `model.xml` contents.
    pub xml: String,
    /// `(file name, contents)` for `meshes/<file name>`, sorted by name.
    pub meshes: Vec<(String, String)>,
}

/// Build `model.xml` and its OBJ meshes. Arguments as [`super::urdf::build`]: one visual
/// mesh, one list of collision pieces and one inertial per part, object frame at rest
/// (panics on other lengths; [`super::artefacts`] checks them).
pub fn build(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    collision: &[Vec<TriMesh>],
    inertials: &[Inertial],
    opts: &ExportOptions,
) -> MjcfBundle {
    let names = link_names(obj);
    MjcfBundle {
        xml: document(obj, &names, meshes, collision, inertials, opts),
        meshes: mesh_files(obj, &names, meshes, collision),
    }
}

/// The MJCF text of [`build`] with the body names given (one per part).
pub(crate) fn document(
    obj: &ArticulatedObject,
    names: &[String],
    meshes: &[TriMesh],
    collision: &[Vec<TriMesh>],
    inertials: &[Inertial],
    opts: &ExportOptions,
) -> String {
    let frames = link_frames(obj);
    let model = safe_unique(std::slice::from_ref(&obj.name)).remove(0);
    let mut x = String::new();
    // Writing into a String cannot fail; the `let _ =` below discard Ok(()).
    let _ = writeln!(x, "<mujoco model=\"{}\">", xml_escape(&model));
    let _ = writeln!(
        x,
        "  <compiler angle=\"radian\" meshdir=\"meshes\" autolimits=\"true\"/>"
    );
    let _ = writeln!(x, "  <asset>");
    for (p, name) in names.iter().enumerate() {
        if !meshes[p].is_empty() {
            let [r, g, b] = PALETTE[p % PALETTE.len()];
            let _ = writeln!(
                x,
                "    <material name=\"{name}_color\" rgba=\"{r} {g} {b} 1\"/>"
            );
            let _ = writeln!(x, "    <mesh name=\"{name}\" file=\"{name}.obj\"/>");
        }
        for (k, _) in pieces(&collision[p]) {
            let file = collision_file(name, k);
            let mesh = file.trim_end_matches(".obj");
            let _ = writeln!(x, "    <mesh name=\"{mesh}\" file=\"{file}\"/>");
        }
    }
    let _ = writeln!(x, "  </asset>");
    let _ = writeln!(x, "  <worldbody>");
    let mut w = BodyWriter {
        obj,
        names,
        frames: &frames,
        meshes,
        collision,
        inertials,
        opts,
        x: &mut x,
    };
    w.body(obj.root(), None, 2);
    let _ = writeln!(x, "  </worldbody>");
    let _ = writeln!(x, "</mujoco>");
    x
}

struct BodyWriter<'a> {
    obj: &'a ArticulatedObject,
    names: &'a [String],
    frames: &'a [Vector3<f64>],
    meshes: &'a [TriMesh],
    collision: &'a [Vec<TriMesh>],
    inertials: &'a [Inertial],
    opts: &'a ExportOptions,
    x: &'a mut String,
}

impl BodyWriter<'_> {
    /// Body `p` (reached through joint `via`, None for the root) and its subtree.
    fn body(&mut self, p: usize, via: Option<usize>, depth: usize) {
        let ind = "  ".repeat(depth);
        let name = &self.names[p];
        let parent_frame = via.map_or(Vector3::zeros(), |k| self.frames[self.obj.joints[k].parent]);
        let pos = self.frames[p] - parent_frame;
        let x = &mut *self.x;
        match self
            .opts
            .frame
            .filter(|f| via.is_none() && !f.is_canonical())
        {
            // The root body on the scan (crate::frame): MuJoCo's quat is w x y z.
            Some(f) => {
                let iso = f.to_scan() * nalgebra::Translation3::from(pos);
                let q = iso.rotation;
                let _ = writeln!(
                    x,
                    "{ind}<body name=\"{name}\" pos=\"{}\" quat=\"{} {} {} {}\">",
                    v(&iso.translation.vector),
                    q.w,
                    q.i,
                    q.j,
                    q.k
                );
            }
            None => {
                let _ = writeln!(x, "{ind}<body name=\"{name}\" pos=\"{}\">", v(&pos));
            }
        }
        if let Some(k) = via {
            let j = &self.obj.joints[k];
            let o = self.opts;
            let mut joint = |jname: String, ty: &str, r: [f64; 2]| {
                let _ = writeln!(
                    x,
                    "{ind}  <joint name=\"{jname}\" type=\"{ty}\" pos=\"0 0 0\" axis=\"{}\" \
                     limited=\"true\" range=\"{} {}\" damping=\"{}\" frictionloss=\"{}\" \
                     actuatorfrclimited=\"true\" actuatorfrcrange=\"{} {}\"/>",
                    v(&j.axis),
                    r[0],
                    r[1],
                    o.damping,
                    o.friction,
                    -o.effort,
                    o.effort
                );
            };
            match j.kind {
                JointKind::Fixed => {}
                JointKind::Revolute => joint(format!("joint_{name}"), "hinge", j.revolute),
                JointKind::Prismatic => joint(format!("joint_{name}"), "slide", j.prismatic),
                JointKind::Screw => {
                    joint(format!("joint_{name}_slide"), "slide", j.prismatic);
                    joint(format!("joint_{name}_turn"), "hinge", j.revolute);
                }
            }
        }
        let i = &self.inertials[p];
        let t = &i.inertia;
        let _ = writeln!(
            x,
            "{ind}  <inertial pos=\"{}\" mass=\"{}\" fullinertia=\"{} {} {} {} {} {}\"/>",
            v(&(i.com - self.frames[p])),
            i.mass,
            t[(0, 0)],
            t[(1, 1)],
            t[(2, 2)],
            t[(0, 1)],
            t[(0, 2)],
            t[(1, 2)]
        );
        if !self.meshes[p].is_empty() {
            let _ = writeln!(
                x,
                "{ind}  <geom name=\"{name}_visual\" type=\"mesh\" mesh=\"{name}\" \
                 material=\"{name}_color\" group=\"1\" contype=\"0\" conaffinity=\"0\"/>"
            );
        }
        for (k, _) in pieces(&self.collision[p]) {
            let _ = writeln!(
                x,
                "{ind}  <geom name=\"{name}_collision_{k}\" type=\"mesh\" \
                 mesh=\"{name}_collision_{k}\" group=\"3\"/>"
            );
        }
        let children: Vec<usize> = self
            .obj
            .joints_topological()
            .into_iter()
            .filter(|&k| self.obj.joints[k].parent == p)
            .collect();
        for k in children {
            self.body(self.obj.joints[k].child, Some(k), depth + 1);
        }
        let _ = writeln!(self.x, "{ind}</body>");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::inertial::{InertialOptions, inertial};
    use crate::export::{collision, urdf};
    use crate::mesh::primitives::part_primitive_mesh;

    fn parts_of(obj: &ArticulatedObject) -> (Vec<TriMesh>, Vec<Vec<TriMesh>>, Vec<Inertial>) {
        let meshes: Vec<TriMesh> = obj
            .parts
            .iter()
            .map(|p| part_primitive_mesh(p).unwrap())
            .collect();
        let inertials = obj
            .parts
            .iter()
            .zip(&meshes)
            .map(|(p, m)| inertial(p, m, &InertialOptions::default()))
            .collect();
        let collision = collision::pieces(obj, &meshes, &Default::default());
        (meshes, collision, inertials)
    }

    #[test]
    fn bodies_joints_and_files_match_the_urdf() {
        let obj = crate::fixtures::eight_part();
        let (meshes, collision, inertials) = parts_of(&obj);
        let opts = ExportOptions::default();
        let m = build(&obj, &meshes, &collision, &inertials, &opts);
        let u = urdf::build(&obj, &meshes, &collision, &inertials, &opts);
        assert_eq!(m.meshes, u.meshes, "both formats share the OBJ files");
        // Every referenced file is one of them, and every file is referenced.
        for (file, _) in &m.meshes {
            assert!(m.xml.contains(&format!("file=\"{file}\"")), "{file}");
            assert!(u.urdf.contains(&format!("meshes/{file}\"")), "{file}");
        }
        assert_eq!(m.xml.matches("file=\"").count(), m.meshes.len());
        assert_eq!(m.xml.matches("<body ").count(), obj.parts.len());
        // 7 joints: one fixed (no element), five with one joint, the screw with two.
        assert_eq!(m.xml.matches("<joint ").count(), 7);
        assert!(
            m.xml
                .contains("<joint name=\"joint_lid_slide\" type=\"slide\"")
        );
        assert!(
            m.xml
                .contains("<joint name=\"joint_lid_turn\" type=\"hinge\"")
        );
        assert!(!m.xml.contains("screw_helper") && u.urdf.contains("lid_screw_helper"));
        let pieces: usize = collision.iter().map(Vec::len).sum();
        assert_eq!(m.xml.matches("group=\"3\"").count(), pieces);
        assert_eq!(m.xml.matches("contype=\"0\"").count(), obj.parts.len());
        // The drawer sits at its joint origin relative to the body's frame (the object frame).
        assert!(
            m.xml
                .contains("<body name=\"drawer0\" pos=\"-0.02 0 0.2\">")
        );
        // Deterministic.
        assert_eq!(build(&obj, &meshes, &collision, &inertials, &opts), m);
    }
}
