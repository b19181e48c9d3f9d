//! Export of an articulated object to the artefacts users take home.
//!
//! Why it exists: a generated object is only useful once it opens in a viewer (GLB) and loads
//! in a simulator (URDF, MJCF). [`artefacts`] builds every file in memory, in one place for
//! the CLI and the service; `export_dir*` writes them, each atomically (temp file + rename):
//!
//! ```text
//! OUT/model.glb          one node per part, kinematic-tree hierarchy, one animation per joint
//! OUT/robot.urdf         one link per part: visual meshes/<link>.obj, one collision per piece
//!                        meshes/<link>_collision_<k>.obj, an inertial every engine accepts,
//!                        effort/velocity/dynamics on every movable joint
//! OUT/model.xml          the same model as MJCF (MuJoCo), sharing meshes/
//! OUT/meshes/*.obj       part meshes and collision pieces in their link frames
//! OUT/robot.zip          robot.urdf + model.xml + meshes/ (deterministic: fixed timestamps, sorted)
//! OUT/object.json        the object itself (io::object_json), to re-export or inspect
//! ```
//!
//! Meshes come from [`mesh_parts`] (marching cubes over each part's SDF, object frame at rest);
//! collision pieces from [`collision::pieces`] (exact primitive hulls, or a convex
//! decomposition of the mesh); [`artefacts`] runs the physics check ([`crate::sim`]) on them
//! and writes its verdict into `object.json` (`sim`).
//!
//! Tiny parts: a part whose mass before the floor ([`inertial::mass_properties`]) is below
//! [`inertial::InertialOptions::min_mass`] is too small to matter to a simulation. When it is
//! a leaf on a fixed joint, the URDF and the MJCF carry it inside its parent (its mesh joins
//! the parent's visual mesh, its pieces the parent's collision pieces, its mass the parent's
//! inertial; no link, body or joint of its own); otherwise it keeps its link with the floored
//! inertial. The GLB and `object.json` always keep every part. [`ExportNote`] records each
//! case, and each part whose inertial fell back to its box.

pub mod collision;
pub mod glb;
pub mod gltf;
pub mod inertial;
pub mod mjcf;
pub mod names;
pub mod urdf;

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{CoreError, CoreResult};
use crate::mesh::{MeshingOptions, TriMesh};
use crate::object::{ArticulatedObject, JointKind};
use inertial::{Inertial, InertialOptions, Source};

/// Errors of the export layer.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The object (or an option) is invalid.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// The glTF writer refused the scene (a bug if the object validated).
    #[error("glTF: {0}")]
    Gltf(#[from] gltf::GltfError),
    /// Writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// Building the zip bundle failed.
    #[error("zip bundle: {0}")]
    Zip(#[from] zip::result::ZipError),
}

impl ExportError {
    /// Machine-readable error kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            ExportError::Core(e) => e.error_type(),
            ExportError::Gltf(_) => "gltf",
            ExportError::Io { .. } => "io",
            ExportError::Zip(_) => "zip",
        }
    }
}

/// Export knobs.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOptions {
    /// Marching-cubes settings.
    pub meshing: MeshingOptions,
    /// URDF `<limit effort>` (N or N·m) on every movable joint; MJCF `actuatorfrcrange` ±effort.
    /// Default 100.
    pub effort: f64,
    /// URDF `<limit velocity>` (m/s or rad/s) on every movable joint (MJCF has no such limit).
    /// Default 1.
    pub velocity: f64,
    /// Viscous joint damping, URDF `<dynamics damping>` / MJCF `damping` (N·m·s/rad for
    /// rotation, N·s/m for translation), on every movable joint. Default 0.1: a door swung by
    /// hand comes to rest instead of oscillating forever, without feeling stuck.
    pub damping: f64,
    /// Dry joint friction, URDF `<dynamics friction>` / MJCF `frictionloss` (N·m or N).
    /// Default 0: parts move freely.
    pub friction: f64,
    /// Density and floors of the part inertials.
    pub inertial: InertialOptions,
    /// How each part's convex collision pieces are made ([`collision`]).
    pub collision: collision::CollisionOptions,
    /// The physics check run on them, reported in `object.json` (`crate::sim`).
    pub sim: crate::sim::SimOptions,
    /// Duration of one sweep lower → upper in the GLB animations (seconds).
    pub sweep_seconds: f32,
    /// The scan's frame (None or the identity: outputs in the canonical frame, as before).
    /// Otherwise the model is put back on the scan: the URDF gains a `world` link and a fixed
    /// joint holding `to_scan`, the MJCF's root body and the GLB's root node hold it, and
    /// `object.json` lists it with the parts and joints in the scan's frame.
    pub frame: Option<crate::frame::ScanFrame>,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            meshing: MeshingOptions::default(),
            effort: 100.0,
            velocity: 1.0,
            damping: 0.1,
            friction: 0.0,
            inertial: InertialOptions::default(),
            collision: collision::CollisionOptions::default(),
            sim: crate::sim::SimOptions::default(),
            sweep_seconds: 2.0,
            frame: None,
        }
    }
}

impl ExportOptions {
    /// Check every field the writers use (not `meshing`, which meshing checks); the error names
    /// the field, the limit and the value.
    pub fn validate(&self) -> CoreResult<()> {
        for (field, v, positive) in [
            ("effort", self.effort, true),
            ("velocity", self.velocity, true),
            ("damping", self.damping, false),
            ("friction", self.friction, false),
            ("sweep_seconds", f64::from(self.sweep_seconds), true),
        ] {
            let ok = v.is_finite() && if positive { v > 0.0 } else { v >= 0.0 };
            if !ok {
                let limit = if positive {
                    "finite and > 0"
                } else {
                    "finite and >= 0"
                };
                return Err(CoreError::invalid(field, limit, v));
            }
        }
        self.inertial.validate()?;
        self.collision.validate()?;
        self.sim.validate()
    }
}

/// Something the export did that a caller may want to tell the user about.
#[derive(Debug, Clone, PartialEq)]
pub enum ExportNote {
    /// A part lighter than `min_mass` on a fixed joint, without children: the URDF and MJCF
    /// carry it inside its parent's link (geometry and mass), not as a link of its own.
    MergedIntoParent {
        /// The part's name.
        part: String,
        /// The parent part's name.
        parent: String,
        /// Its mass before the floor (kg).
        mass: f64,
    },
    /// A part lighter than `min_mass` that moves or has children: kept, with the floor mass.
    MassFloored {
        /// The part's name.
        part: String,
        /// Its mass before the floor (kg), merged tiny children included.
        mass: f64,
        /// The mass written (kg).
        written: f64,
    },
    /// The part's (non-empty) mesh volume was not sane (overlapping shells, open, inside out
    /// or far larger than the box): its inertial is its solid box's.
    BoxInertial {
        /// The part's name.
        part: String,
        /// The mesh's signed volume (m³).
        mesh_volume: f64,
        /// The box's volume (m³).
        box_volume: f64,
    },
}

impl std::fmt::Display for ExportNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ExportNote::MergedIntoParent { part, parent, mass } => write!(
                f,
                "part {part:?} ({mass:.3e} kg, fixed leaf) is too small to simulate on its own: merged into {parent:?} in robot.urdf and model.xml"
            ),
            ExportNote::MassFloored {
                part,
                mass,
                written,
            } => write!(
                f,
                "part {part:?} ({mass:.3e} kg) is too small to matter: written with the floor mass {written} kg"
            ),
            ExportNote::BoxInertial {
                part,
                mesh_volume,
                box_volume,
            } => write!(
                f,
                "part {part:?}: mesh volume {mesh_volume:.3e} m³ is not usable (box {box_volume:.3e} m³): inertial of its box"
            ),
        }
    }
}

/// What [`export_dir`] wrote.
#[derive(Debug, Clone)]
pub struct ExportReport {
    /// Files written, relative to the output directory.
    pub files: Vec<PathBuf>,
    /// Triangles per part.
    pub triangles: Vec<usize>,
    /// Parts whose mesh came out empty (they get no geometry).
    pub empty_parts: Vec<String>,
    /// What the export decided about tiny parts and inertials (module docs).
    pub notes: Vec<ExportNote>,
    /// The physics check of the collision pieces written (`crate::sim`).
    pub sim: crate::sim::SimReport,
}

/// Every artefact of one object, in memory.
#[derive(Debug, Clone)]
pub struct Artefacts {
    /// `(path relative to the export directory, bytes)`: `model.glb`, `robot.urdf`,
    /// `model.xml`, `meshes/*.obj` (sorted), `robot.zip`, `object.json`, in that order.
    pub files: Vec<(String, Vec<u8>)>,
    /// What the export decided about tiny parts and inertials.
    pub notes: Vec<ExportNote>,
    /// The physics check of the collision pieces written (`crate::sim`; also in object.json).
    pub sim: crate::sim::SimReport,
}

impl Artefacts {
    /// The bytes of `name` (e.g. `"robot.zip"`), if it is one of the files.
    pub fn file(&self, name: &str) -> Option<&[u8]> {
        self.files
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, b)| b.as_slice())
    }

    /// Remove `name` from the files and return its bytes.
    pub fn take(&mut self, name: &str) -> Option<Vec<u8>> {
        let i = self.files.iter().position(|(n, _)| n == name)?;
        Some(self.files.remove(i).1)
    }
}

pub use crate::mesh::mesh_parts;

/// Build every artefact of `obj` in memory. `meshes[p]` is part p's visual mesh and
/// `collision[p]` its convex collision pieces, object frame at rest, one entry per part;
/// `repairs` (the joint repairs generation made) are listed in `object.json`.
pub fn artefacts(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    collision: &[Vec<TriMesh>],
    repairs: &[crate::graph::repair::Repair],
    opts: &ExportOptions,
) -> Result<Artefacts, ExportError> {
    obj.validate()?;
    opts.validate()?;
    for (field, n) in [("meshes", meshes.len()), ("collision", collision.len())] {
        if n != obj.parts.len() {
            return Err(CoreError::invalid(
                field,
                format!("one entry per part ({})", obj.parts.len()),
                n,
            )
            .into());
        }
    }
    let sim = SimModel::new(obj, meshes, collision, &opts.inertial);
    let urdf = urdf::document(
        &sim.object,
        &sim.names,
        &sim.meshes,
        &sim.collision,
        &sim.inertials,
        opts,
    );
    let mjcf = mjcf::document(
        &sim.object,
        &sim.names,
        &sim.meshes,
        &sim.collision,
        &sim.inertials,
        opts,
    );
    let mesh_files = urdf::mesh_files(&sim.object, &sim.names, &sim.meshes, &sim.collision);
    let zip = zip_bundle(&urdf, &mjcf, &mesh_files)?;
    let report = crate::sim::check(&sim.object, &sim.collision, &opts.sim)?;
    let sim_doc = crate::io::verdict::sim_json(&sim.object, &report);
    let mut files = vec![
        ("model.glb".to_string(), glb::build(obj, meshes, opts)?),
        ("robot.urdf".to_string(), urdf.into_bytes()),
        ("model.xml".to_string(), mjcf.into_bytes()),
    ];
    files.extend(
        mesh_files
            .into_iter()
            .map(|(name, text)| (format!("meshes/{name}"), text.into_bytes())),
    );
    files.push(("robot.zip".to_string(), zip));
    files.push((
        "object.json".to_string(),
        crate::io::object_json::to_string_with(obj, repairs, Some(sim_doc), opts.frame.as_ref())
            .into_bytes(),
    ));
    Ok(Artefacts {
        files,
        notes: sim.notes,
        sim: report,
    })
}

/// What the simulation formats describe: the object after its tiny fixed leaves went into
/// their parents (module docs), with each remaining part's link name (the full object's, so
/// names never shift), visual mesh, collision pieces and floored inertial.
struct SimModel {
    object: ArticulatedObject,
    names: Vec<String>,
    meshes: Vec<TriMesh>,
    collision: Vec<Vec<TriMesh>>,
    inertials: Vec<Inertial>,
    notes: Vec<ExportNote>,
}

impl SimModel {
    fn new(
        obj: &ArticulatedObject,
        meshes: &[TriMesh],
        collision: &[Vec<TriMesh>],
        opts: &InertialOptions,
    ) -> SimModel {
        let n = obj.parts.len();
        let all_names = names::link_names(obj);
        let mut notes = Vec::new();
        let solids: Vec<Inertial> = obj
            .parts
            .iter()
            .zip(meshes)
            .map(|(part, mesh)| {
                let (solid, source) = inertial::mass_properties(part, mesh, opts.density);
                if let (Source::Box { mesh_volume }, false) = (source, mesh.is_empty()) {
                    notes.push(ExportNote::BoxInertial {
                        part: part.name.clone(),
                        mesh_volume,
                        box_volume: part.volume(),
                    });
                }
                solid
            })
            .collect();
        // Where each part goes: itself, or its parent for a tiny fixed leaf.
        let into: Vec<usize> = (0..n)
            .map(|p| match obj.parent_joint(p) {
                Some(k)
                    if solids[p].mass < opts.min_mass
                        && obj.joints[k].kind == JointKind::Fixed
                        && obj.joints.iter().all(|j| j.parent != p) =>
                {
                    obj.joints[k].parent
                }
                _ => p,
            })
            .collect();
        let kept: Vec<usize> = (0..n).filter(|&p| into[p] == p).collect();
        let index = |p: usize| kept.iter().position(|&q| q == into[p]).unwrap_or(0);
        let mut sim = SimModel {
            object: ArticulatedObject {
                parts: kept.iter().map(|&p| obj.parts[p].clone()).collect(),
                joints: obj
                    .joints
                    .iter()
                    .filter(|j| into[j.child] == j.child)
                    .map(|j| crate::object::Joint {
                        parent: index(j.parent),
                        child: index(j.child),
                        ..j.clone()
                    })
                    .collect(),
                ..obj.clone()
            },
            names: kept.iter().map(|&p| all_names[p].clone()).collect(),
            meshes: Vec::with_capacity(kept.len()),
            collision: Vec::with_capacity(kept.len()),
            inertials: Vec::with_capacity(kept.len()),
            notes: Vec::new(),
        };
        for &p in &kept {
            let mut solid = solids[p];
            let mut mesh = meshes[p].clone();
            let mut pieces = collision[p].clone();
            for c in (0..n).filter(|&c| c != p && into[c] == p) {
                solid = solid.combine(&solids[c]);
                append(&mut mesh, &meshes[c]);
                pieces.extend(collision[c].iter().cloned());
                notes.push(ExportNote::MergedIntoParent {
                    part: obj.parts[c].name.clone(),
                    parent: obj.parts[p].name.clone(),
                    mass: solids[c].mass,
                });
            }
            let written = inertial::floored(&solid, opts);
            if solid.mass < opts.min_mass {
                notes.push(ExportNote::MassFloored {
                    part: obj.parts[p].name.clone(),
                    mass: solid.mass,
                    written: written.mass,
                });
            }
            sim.meshes.push(mesh);
            sim.collision.push(pieces);
            sim.inertials.push(written);
        }
        sim.notes = notes;
        sim
    }
}

/// Append `b`'s triangles to `a` (both in the same frame).
fn append(a: &mut TriMesh, b: &TriMesh) {
    let base = a.positions.len() as u32;
    a.positions.extend_from_slice(&b.positions);
    a.triangles.extend(
        b.triangles
            .iter()
            .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
    );
}

/// Write all artefacts for `obj` into `out` (created if missing), with the collision pieces of
/// [`collision::pieces`].
pub fn export_dir(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    out: &Path,
    opts: &ExportOptions,
) -> Result<ExportReport, ExportError> {
    export_dir_with_repairs(obj, meshes, &[], out, opts)
}

/// [`export_dir`] of a generated object, with the joint repairs generation made listed in
/// `object.json` (`repairs`).
pub fn export_dir_with_repairs(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    repairs: &[crate::graph::repair::Repair],
    out: &Path,
    opts: &ExportOptions,
) -> Result<ExportReport, ExportError> {
    // Checked before the decomposition runs on them (artefacts checks again, cheaply).
    opts.validate()?;
    let pieces = collision::pieces(obj, meshes, &opts.collision);
    export_dir_with_collision(obj, meshes, &pieces, repairs, out, opts)
}

/// Write [`artefacts`] into `out` (created if missing), each file atomically.
pub fn export_dir_with_collision(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    collision: &[Vec<TriMesh>],
    repairs: &[crate::graph::repair::Repair],
    out: &Path,
    opts: &ExportOptions,
) -> Result<ExportReport, ExportError> {
    let art = artefacts(obj, meshes, collision, repairs, opts)?;
    std::fs::create_dir_all(out.join("meshes")).map_err(|source| ExportError::Io {
        path: out.to_path_buf(),
        source,
    })?;
    let mut files = Vec::with_capacity(art.files.len());
    for (rel, bytes) in &art.files {
        write_atomic(&out.join(rel), bytes)?;
        files.push(PathBuf::from(rel));
    }
    Ok(ExportReport {
        files,
        triangles: meshes.iter().map(|m| m.triangles.len()).collect(),
        empty_parts: obj
            .parts
            .iter()
            .zip(meshes)
            .filter(|(_, m)| m.is_empty())
            .map(|(p, _)| p.name.clone())
            .collect(),
        notes: art.notes,
        sim: art.sim,
    })
}

/// `robot.urdf`, `model.xml` and their meshes (`(file name, OBJ text)` under `meshes/`) as one
/// zip (fixed timestamps, so identical input gives identical bytes).
pub fn zip_bundle(
    urdf: &str,
    mjcf: &str,
    meshes: &[(String, String)],
) -> Result<Vec<u8>, ExportError> {
    let mut zw = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .last_modified_time(zip::DateTime::default());
    let io = |source| ExportError::Io {
        path: PathBuf::from("robot.zip"),
        source,
    };
    for (name, text) in [("robot.urdf", urdf), ("model.xml", mjcf)] {
        zw.start_file(name, options)?;
        zw.write_all(text.as_bytes()).map_err(io)?;
    }
    for (name, text) in meshes {
        zw.start_file(format!("meshes/{name}"), options)?;
        zw.write_all(text.as_bytes()).map_err(io)?;
    }
    Ok(zw.finish()?.into_inner())
}

/// Write `bytes` to `path` via a temporary sibling and a rename, so readers never see a
/// half-written file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    crate::io::atomic::write(path, bytes).map_err(|e| ExportError::Io {
        path: e.path,
        source: e.source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::box_part;
    use crate::mesh::primitives::part_primitive_mesh;
    use crate::object::Joint;
    use nalgebra::{Point3, Vector3};

    /// A body with a tiny fixed knob (a leaf), a tiny fixed bracket holding a tiny fixed pin,
    /// and a tiny hinged flap.
    fn knobbly() -> ArticulatedObject {
        let fixed = |parent, child, at: [f64; 3]| Joint {
            parent,
            child,
            kind: JointKind::Fixed,
            axis: Vector3::z(),
            origin: Point3::from(at),
            revolute: [0.0, 0.0],
            prismatic: [0.0, 0.0],
        };
        ArticulatedObject {
            name: "knobbly".into(),
            category: None,
            parts: vec![
                box_part("body", [0.0, 0.0, 0.5], [0.3, 0.3, 0.5]),
                box_part("knob", [-0.305, 0.0, 0.5], [0.005, 0.005, 0.005]),
                box_part("bracket", [0.305, 0.0, 0.5], [0.005, 0.005, 0.005]),
                box_part("pin", [0.315, 0.0, 0.5], [0.005, 0.002, 0.002]),
                box_part("flap", [0.0, 0.305, 0.5], [0.005, 0.005, 0.005]),
            ],
            joints: vec![
                fixed(0, 1, [-0.3, 0.0, 0.5]),
                fixed(0, 2, [0.3, 0.0, 0.5]),
                fixed(2, 3, [0.31, 0.0, 0.5]),
                Joint {
                    kind: JointKind::Revolute,
                    revolute: [0.0, 1.0],
                    ..fixed(0, 4, [0.0, 0.3, 0.5])
                },
            ],
        }
    }

    #[test]
    fn tiny_fixed_leaves_merge_into_their_parent() {
        let obj = knobbly();
        obj.validate().unwrap();
        let meshes: Vec<TriMesh> = obj
            .parts
            .iter()
            .map(|p| part_primitive_mesh(p).unwrap())
            .collect();
        let opts = InertialOptions::default();
        let sim = SimModel::new(
            &obj,
            &meshes,
            &collision::pieces(&obj, &meshes, &Default::default()),
            &opts,
        );
        // The knob and the pin go into their parents; the bracket (it has a child) and the
        // flap (it moves) keep their links with the floor mass.
        assert_eq!(sim.names, ["body", "bracket", "flap"]);
        sim.object.validate().unwrap();
        assert_eq!(sim.object.joints.len(), 2);
        assert_eq!(
            sim.collision[0].len(),
            2,
            "the body carries the knob's piece"
        );
        assert_eq!(
            sim.collision[1].len(),
            2,
            "the bracket carries the pin's piece"
        );
        assert_eq!(
            sim.meshes[0].triangles.len(),
            meshes[0].triangles.len() + meshes[1].triangles.len()
        );
        let solid = |p: usize| inertial::mass_properties(&obj.parts[p], &meshes[p], 300.0).0;
        let body = inertial::floored(&solid(0).combine(&solid(1)), &opts);
        assert_eq!(sim.inertials[0], body);
        assert!(sim.inertials[0].mass > solid(0).mass);
        assert_eq!(sim.inertials[1].mass, opts.min_mass);
        assert_eq!(sim.inertials[2].mass, opts.min_mass);
        let merged: Vec<(&str, &str)> = sim
            .notes
            .iter()
            .filter_map(|n| match n {
                ExportNote::MergedIntoParent { part, parent, .. } => {
                    Some((part.as_str(), parent.as_str()))
                }
                _ => None,
            })
            .collect();
        assert_eq!(merged, [("knob", "body"), ("pin", "bracket")]);
        let floored: Vec<&str> = sim
            .notes
            .iter()
            .filter_map(|n| match n {
                ExportNote::MassFloored { part, .. } => Some(part.as_str()),
                _ => None,
            })
            .collect();
        assert_eq!(floored, ["bracket", "flap"]);

        // The artefacts: no knob or pin link, body and joint, but the GLB keeps every part.
        let art = artefacts(
            &obj,
            &meshes,
            &collision::pieces(&obj, &meshes, &Default::default()),
            &[],
            &ExportOptions::default(),
        )
        .unwrap();
        assert_eq!(art.notes, sim.notes);
        for f in ["robot.urdf", "model.xml"] {
            let text = std::str::from_utf8(art.file(f).unwrap()).unwrap();
            assert!(
                !text.contains("\"knob\"") && !text.contains("\"pin\""),
                "{f}"
            );
            assert!(text.contains("\"bracket\""), "{f}");
        }
        let names: Vec<&str> = art.files.iter().map(|(n, _)| n.as_str()).collect();
        assert!(names.contains(&"meshes/body_collision_1.obj"), "{names:?}");
        assert!(!names.iter().any(|n| n.contains("knob")), "{names:?}");
        let glb = gltf::read_glb_json(art.file("model.glb").unwrap()).unwrap();
        let nodes = glb["nodes"].as_array().unwrap();
        assert!(nodes.iter().any(|n| n["name"] == "knob"));
        assert!(nodes.iter().any(|n| n["name"] == "pin"));
        let json = std::str::from_utf8(art.file("object.json").unwrap()).unwrap();
        assert!(json.contains("\"knob\""));
    }

    #[test]
    fn artefacts_are_listed_in_order_and_lengths_are_checked() {
        let obj = crate::fixtures::cabinet();
        let meshes: Vec<TriMesh> = obj
            .parts
            .iter()
            .map(|p| part_primitive_mesh(p).unwrap())
            .collect();
        let opts = ExportOptions::default();
        let pieces = collision::pieces(&obj, &meshes, &Default::default());
        let art = artefacts(&obj, &meshes, &pieces, &[], &opts).unwrap();
        let names: Vec<&str> = art.files.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names[..3], ["model.glb", "robot.urdf", "model.xml"]);
        assert_eq!(names[names.len() - 2..], ["robot.zip", "object.json"]);
        let n: usize = pieces.iter().map(Vec::len).sum();
        assert_eq!(names.len(), 5 + obj.parts.len() + n);
        assert!(art.sim.clean, "{:?}", art.sim);
        let e = artefacts(&obj, &meshes, &[], &[], &opts)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("collision") && e.contains("one entry per part (3)") && e.contains('0'),
            "{e}"
        );
    }
}
