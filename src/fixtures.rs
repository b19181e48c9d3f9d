//! Small built-in objects for demos, tests and benchmarks.
//!
//! Why it exists: the README's first command, the tests and the benchmarks all need real
//! articulated objects without any data set. [`cabinet`] is the hand-written example shipped
//! as `examples/cabinet.json` (3 parts: body, door, drawer); [`eight_part`] builds an 8-part
//! object using every joint type (revolute, prismatic, screw, fixed), the worst case of export.
//! [`tiny_weights`] writes a tiny, untrained but complete weights directory, for the service
//! tests and the API fuzzing run, where the engine must run for real but fast.

use std::path::Path;

use nalgebra::{Point3, Vector3};

use crate::object::{ArticulatedObject, Joint, JointKind, Part};
use crate::shape::{Axis, PartShape, Primitive};

/// The example cabinet JSON (`examples/cabinet.json`).
pub const CABINET_JSON: &str = include_str!("../examples/cabinet.json");

/// Write a tiny, randomly initialised (untrained) but real weights directory into `dir`:
/// denoiser (width 16, one layer, every category), shape prior and manifest. The whole engine
/// path (denoiser, schedule, projection, shape decoder, meshing, export) runs on it in
/// milliseconds per step.
pub fn tiny_weights(dir: &Path) -> Result<(), crate::model::weights::WeightsError> {
    use crate::io::manifest::{Entry, Manifest, to_string};
    use crate::model::denoiser::{Denoiser, DenoiserConfig};
    use crate::model::shape_prior::{ShapePrior, ShapePriorConfig};
    use crate::model::weights::{WeightsError, save};
    let io = |path: &Path| {
        let path = path.display().to_string();
        move |source| WeightsError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let device = crate::model::cpu();
    let sp_cfg = ShapePriorConfig {
        latent: 128,
        decoder_hidden: 16,
        decoder_blocks: 1,
        encoder_hidden: 16,
        encoder_blocks: 1,
        pe_freqs: 2,
        code_every_block: false,
    };
    let sp = ShapePrior::new(&sp_cfg, &device);
    let sp_sha = save(&sp, &dir.join("shape_prior.safetensors"))?;
    let categories: Vec<String> = crate::data::categories::CATEGORIES
        .iter()
        .map(|s| s.to_string())
        .collect();
    let dn_cfg = DenoiserConfig {
        width: 16,
        layers: 1,
        head_channels: 16,
        t_pe_dim: 8,
        slot_pe_dim: 8,
        node_head_hidden: vec![16],
        edge_head_hidden: vec![16],
        categories: categories.len(),
        legacy_edge_embedding: false,
        category_layers: false,
    };
    let dn = Denoiser::new(&dn_cfg, &device).expect("the tiny denoiser config is valid");
    let dn_sha = save(&dn, &dir.join("denoiser.safetensors"))?;
    let m = Manifest {
        shape_prior: Entry {
            file: "shape_prior.safetensors".into(),
            sha256: sp_sha,
            config: sp_cfg,
        },
        denoiser: Entry {
            file: "denoiser.safetensors".into(),
            sha256: dn_sha,
            config: dn_cfg,
        },
        codebook: None,
        feature_scales: crate::graph::FeatureScales::default(),
        categories,
        data: serde_json::json!({"note": "untrained test weights"}),
        training: serde_json::Value::Null,
        metrics: serde_json::Value::Null,
    };
    let path = dir.join("manifest.json");
    std::fs::write(&path, to_string(&m)).map_err(io(&path))
}

/// A part with a plain box shape centred at `c` with half-extents `h` (tests and examples).
pub fn box_part(name: &str, c: [f64; 3], h: [f64; 3]) -> Part {
    Part {
        name: name.into(),
        half_extents: Vector3::from(h),
        center: Vector3::from(c),
        shape: PartShape::Box,
    }
}

/// The example cabinet: body, a revolute door and a prismatic drawer.
pub fn cabinet() -> ArticulatedObject {
    // The file is part of the crate and covered by tests; failing to parse it is a build bug.
    crate::io::object_json::from_str(CABINET_JSON).expect("examples/cabinet.json is valid")
}

fn cuboid(c: [f64; 3], h: [f64; 3]) -> Primitive {
    Primitive::Cuboid {
        center: Vector3::from(c),
        half_extents: Vector3::from(h),
    }
}

/// An 8-part object: a tall cabinet with two doors, three drawers, a screw-lid jar on top and
/// a fixed plinth. Exercises every joint type.
pub fn eight_part() -> ArticulatedObject {
    let part = |name: &str, c: [f64; 3], h: [f64; 3], shape: PartShape| Part {
        name: name.into(),
        half_extents: Vector3::from(h),
        center: Vector3::from(c),
        shape,
    };
    let mut parts = vec![
        part(
            "body",
            [0.0, 0.0, 0.6],
            [0.25, 0.4, 0.5],
            PartShape::Primitives(vec![
                cuboid([0.24, 0.0, 0.0], [0.01, 0.4, 0.5]),
                cuboid([0.0, -0.39, 0.0], [0.25, 0.01, 0.5]),
                cuboid([0.0, 0.39, 0.0], [0.25, 0.01, 0.5]),
                cuboid([0.0, 0.0, 0.49], [0.25, 0.4, 0.01]),
                cuboid([0.0, 0.0, -0.49], [0.25, 0.4, 0.01]),
                cuboid([0.0, 0.0, 0.0], [0.25, 0.38, 0.01]),
            ]),
        ),
        part(
            "plinth",
            [0.0, 0.0, 0.05],
            [0.24, 0.38, 0.05],
            PartShape::Box,
        ),
    ];
    for (k, y) in [-0.195, 0.195].into_iter().enumerate() {
        parts.push(part(
            &format!("door{k}"),
            [-0.26, y, 0.85],
            [0.01, 0.19, 0.24],
            PartShape::Primitives(vec![cuboid([0.0, 0.0, 0.0], [0.01, 0.19, 0.24])]),
        ));
    }
    for (k, z) in [0.2, 0.35, 0.5].into_iter().enumerate() {
        parts.push(part(
            &format!("drawer{k}"),
            [-0.02, 0.0, z],
            [0.24, 0.37, 0.065],
            PartShape::Primitives(vec![
                cuboid([-0.23, 0.0, 0.0], [0.01, 0.37, 0.065]),
                cuboid([0.0, 0.0, -0.06], [0.24, 0.36, 0.005]),
                cuboid([0.23, 0.0, -0.01], [0.01, 0.36, 0.05]),
            ]),
        ));
    }
    parts.push(part(
        "lid",
        [0.0, 0.0, 1.13],
        [0.08, 0.08, 0.03],
        PartShape::Primitives(vec![Primitive::Cylinder {
            center: Vector3::zeros(),
            axis: Axis::Z,
            radius: 0.08,
            half_height: 0.03,
        }]),
    ));
    let joint = |parent, child, kind, axis: [f64; 3], origin: [f64; 3], r, p| Joint {
        parent,
        child,
        kind,
        axis: Vector3::from(axis),
        origin: Point3::from(origin),
        revolute: r,
        prismatic: p,
    };
    let z = [0.0, 0.0];
    let joints = vec![
        joint(
            0,
            1,
            JointKind::Fixed,
            [0.0, 0.0, 1.0],
            [0.0, 0.0, 0.1],
            z,
            z,
        ),
        joint(
            0,
            2,
            JointKind::Revolute,
            [0.0, 0.0, 1.0],
            [-0.27, -0.385, 0.85],
            [0.0, 1.6],
            z,
        ),
        joint(
            0,
            3,
            JointKind::Revolute,
            [0.0, 0.0, -1.0],
            [-0.27, 0.385, 0.85],
            [0.0, 1.6],
            z,
        ),
        joint(
            0,
            4,
            JointKind::Prismatic,
            [-1.0, 0.0, 0.0],
            [-0.02, 0.0, 0.2],
            z,
            [0.0, 0.35],
        ),
        joint(
            0,
            5,
            JointKind::Prismatic,
            [-1.0, 0.0, 0.0],
            [-0.02, 0.0, 0.35],
            z,
            [0.0, 0.35],
        ),
        joint(
            0,
            6,
            JointKind::Prismatic,
            [-1.0, 0.0, 0.0],
            [-0.02, 0.0, 0.5],
            z,
            [0.0, 0.35],
        ),
        joint(
            0,
            7,
            JointKind::Screw,
            [0.0, 0.0, 1.0],
            [0.0, 0.0, 1.13],
            [0.0, 12.0],
            [0.0, 0.02],
        ),
    ];
    ArticulatedObject {
        name: "eight_part_cabinet".into(),
        category: Some("StorageFurniture".into()),
        parts,
        joints,
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn fixtures_are_valid() {
        super::cabinet().validate().unwrap();
        super::eight_part().validate().unwrap();
        assert_eq!(super::eight_part().parts.len(), 8);
    }
}
