//! Export of an articulated object to the artefacts users take home.
//!
//! Why it exists: a generated object is only useful once it opens in a viewer (GLB) and loads
//! in a simulator (URDF). `export_dir` writes, atomically (temp file + rename):
//!
//! ```text
//! OUT/model.glb          one node per part, kinematic-tree hierarchy, one animation per joint
//! OUT/robot.urdf         one link per part, meshes/<link>.obj, effort/velocity always present
//! OUT/meshes/<link>.obj  part meshes in their link frames
//! OUT/robot.zip          robot.urdf + meshes/ (deterministic: fixed timestamps, sorted)
//! OUT/object.json        the object itself (io::object_json), to re-export or inspect
//! ```
//!
//! Meshes come from [`mesh_parts`] (marching cubes over each part's SDF, object frame at rest).

pub mod collision;
pub mod glb;
pub mod gltf;
pub mod names;
pub mod urdf;

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::CoreError;
use crate::mesh::{MeshingOptions, TriMesh};
use crate::object::ArticulatedObject;

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
    /// URDF `<limit effort>` (N or N·m) written on every movable joint.
    pub effort: f64,
    /// URDF `<limit velocity>` (m/s or rad/s) written on every movable joint.
    pub velocity: f64,
    /// Density (kg/m³) of a part's box, for URDF inertials.
    pub density: f64,
    /// Duration of one sweep lower → upper in the GLB animations (seconds).
    pub sweep_seconds: f32,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            meshing: MeshingOptions::default(),
            effort: 100.0,
            velocity: 1.0,
            density: 300.0,
            sweep_seconds: 2.0,
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
}

pub use crate::mesh::mesh_parts;

/// Write all artefacts for `obj` into `out` (created if missing).
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
    obj.validate()?;
    if meshes.len() != obj.parts.len() {
        return Err(CoreError::invalid(
            "meshes",
            format!("one mesh per part ({})", obj.parts.len()),
            meshes.len(),
        )
        .into());
    }
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ExportError::Io { path, source }
    };
    std::fs::create_dir_all(out.join("meshes")).map_err(io(out))?;
    let bundle = urdf::build(obj, meshes, opts);
    let glb = glb::build(obj, meshes, opts)?;
    let mut files = Vec::new();
    let mut put = |rel: &str, bytes: &[u8]| -> Result<(), ExportError> {
        write_atomic(&out.join(rel), bytes)?;
        files.push(PathBuf::from(rel));
        Ok(())
    };
    put("model.glb", &glb)?;
    put("robot.urdf", bundle.urdf.as_bytes())?;
    for (name, text) in &bundle.meshes {
        put(&format!("meshes/{name}"), text.as_bytes())?;
    }
    put("robot.zip", &zip_bundle(&bundle)?)?;
    put(
        "object.json",
        crate::io::object_json::to_string_with_repairs(obj, repairs).as_bytes(),
    )?;
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
    })
}

/// The URDF and its meshes as one zip (fixed timestamps, so identical input gives identical bytes).
pub fn zip_bundle(bundle: &urdf::UrdfBundle) -> Result<Vec<u8>, ExportError> {
    let mut zw = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .last_modified_time(zip::DateTime::default());
    let io = |source| ExportError::Io {
        path: PathBuf::from("robot.zip"),
        source,
    };
    zw.start_file("robot.urdf", options)?;
    zw.write_all(bundle.urdf.as_bytes()).map_err(io)?;
    for (name, text) in &bundle.meshes {
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
