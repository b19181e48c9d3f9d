//! Shared helpers for integration tests: the real validators and random objects.
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

use nalgebra::{Point3, Vector3};
use physnap::shape::PartShape;
use physnap::{ArticulatedObject, Joint, JointKind, Part};

/// Run the Khronos glTF-Validator on a GLB; returns its JSON report. Panics (fails the test)
/// when the validator cannot run: it is a required test tool (`bash .ci/setup`).
pub fn gltf_validate(glb: &Path) -> serde_json::Value {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/tools/validate_gltf.js");
    let out = Command::new("node")
        .arg(script)
        .arg(glb)
        .output()
        .expect("node is required for the glTF validator: run `bash .ci/setup`");
    assert!(
        out.status.code() == Some(0) || out.status.code() == Some(1),
        "glTF validator did not run (run `npm ci --prefix tests/tools`): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("validator prints JSON")
}

/// Assert the GLB has zero validator errors and zero warnings.
pub fn assert_gltf_clean(glb: &Path) {
    let report = gltf_validate(glb);
    assert_eq!(report["numErrors"], 0, "validator errors: {report:#}");
    assert_eq!(report["numWarnings"], 0, "validator warnings: {report:#}");
}

/// Run urdfdom's `check_urdf`; panics with its output on failure.
pub fn check_urdf(urdf: &Path) -> String {
    let out = Command::new("check_urdf")
        .arg(urdf)
        .output()
        .expect("check_urdf is required (Debian liburdfdom-tools): run `bash .ci/setup`");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "check_urdf failed:\n{text}");
    text
}

/// Tiny deterministic PRNG (SplitMix64) so property tests can draw Gaussians from a seed.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    pub fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
    pub fn unit_vector(&mut self) -> Vector3<f64> {
        loop {
            let v = Vector3::new(self.gauss(), self.gauss(), self.gauss());
            if v.norm() > 1e-3 {
                return v.normalize();
            }
        }
    }
}

/// A random valid object with `n` parts: random boxes, a random tree, random joint types.
pub fn random_object(rng: &mut Rng, n: usize) -> ArticulatedObject {
    let parts = (0..n)
        .map(|i| Part {
            name: format!("p{i}"),
            half_extents: Vector3::new(
                rng.range(0.01, 0.5),
                rng.range(0.01, 0.5),
                rng.range(0.01, 0.5),
            ),
            center: Vector3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(0.0, 2.0),
            ),
            shape: PartShape::Latent((0..128).map(|_| rng.gauss() as f32).collect()),
        })
        .collect();
    let joints = (1..n)
        .map(|child| {
            let parent = rng.below(child);
            let kind = [
                JointKind::Revolute,
                JointKind::Prismatic,
                JointKind::Screw,
                JointKind::Fixed,
            ][rng.below(4)];
            let range = |rng: &mut Rng, scale: f64| {
                let a = rng.range(-scale, scale);
                [a, a + rng.range(0.01, scale)]
            };
            Joint {
                parent,
                child,
                kind,
                axis: rng.unit_vector(),
                origin: Point3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(0.0, 2.0),
                ),
                revolute: if kind.rotates() {
                    range(rng, 2.0)
                } else {
                    [0.0, 0.0]
                },
                prismatic: if kind.slides() {
                    range(rng, 0.5)
                } else {
                    [0.0, 0.0]
                },
            }
        })
        .collect();
    ArticulatedObject {
        name: "random".into(),
        category: None,
        parts,
        joints,
    }
}
