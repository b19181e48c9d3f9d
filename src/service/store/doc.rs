//! How a [`JobSpec`] is stored: its knobs as a JSON document, its points as an f32le blob.
//!
//! Why it exists: both stores (SQLite and PostgreSQL) keep the same two columns, and a row
//! written by any earlier release must still load as the job it was accepted as. The
//! document's defaults say what a row without a later knob ran with.

use serde::{Deserialize, Serialize};

use super::StoreError;
use crate::engine::generate::{JointMotion, RepairMode, Retrieval};
use crate::engine::sample::Sampler;
use crate::engine::schedule::{NUM_STEPS, timesteps};
use crate::service::spec::JobSpec;

/// Persistence form of [`JobSpec`] (points go in a separate f32le blob).
#[derive(Serialize, Deserialize)]
struct SpecDoc {
    category: Option<(usize, String)>,
    w_pc: f64,
    w_pen: f64,
    w_mob: f64,
    /// n_g as in the paper: the steps with diffusion time t < this are guided.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    n_g_t: Option<u32>,
    /// Rows written before n_g had the paper's meaning hold it as a count: the last this many
    /// of the `steps` reverse steps were guided ([`threshold_of_final_steps`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    n_g: Option<u32>,
    tau: f64,
    #[serde(default)]
    guidance_max_step: Option<f64>,
    /// Absent in specs stored before refinement existed: those were accepted without it.
    #[serde(default)]
    refine_steps: u32,
    /// Absent in specs stored before physics-only refinement existed: those ran none.
    #[serde(default)]
    refine_physics_steps: u32,
    sampler: String,
    #[serde(default)]
    eta: f64,
    steps: u32,
    seed: u64,
    samples: u32,
    deadline_seconds: f64,
    preview_every: u32,
    resolution: u32,
    /// Rows written before retrieval existed ran without it.
    #[serde(default = "retrieval_off")]
    retrieval: String,
    /// Rows written before category guidance existed ran without it.
    #[serde(default)]
    category_guidance: f64,
    /// Rows written before the guidance could be limited to t < 500 guided every step.
    #[serde(default = "every_step")]
    category_guidance_below: u32,
    /// Rows written before joint motions could be chosen kept NAP's screws.
    #[serde(default = "joint_motion_screw")]
    joint_motion: String,
    /// Rows written before cameras could be given had none.
    #[serde(default)]
    cameras: Vec<[f32; 3]>,
    /// ... and so no ℓ_free.
    #[serde(default)]
    w_free: f64,
    /// Rows written before repair could be chosen were accepted by a pipeline without it.
    #[serde(default = "repair_off")]
    repair: String,
    /// ... and without a scale hypothesis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    scale: Option<f64>,
    /// ... and with the scan in the canonical frame: `(up, yaw, translation)` of the scan's
    /// frame when it was estimated at submission (`frame: auto`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frame: Option<([f64; 3], f64, [f64; 3])>,
}

/// The diffusion-time threshold that guides exactly the last `last` of `steps` reverse steps
/// over the schedule: t < (the time of the `last`-th last step) + 1. How rows stored with
/// n_g as a count of final steps are read.
fn threshold_of_final_steps(steps: u32, last: u32) -> u32 {
    let times = timesteps(NUM_STEPS, steps as usize);
    let n = (last as usize).min(times.len());
    if n == 0 {
        0
    } else {
        (times[times.len() - n] + 1) as u32
    }
}

fn repair_off() -> String {
    RepairMode::Off.as_str().into()
}

fn joint_motion_screw() -> String {
    crate::engine::generate::JointMotion::Screw.as_str().into()
}

fn every_step() -> u32 {
    NUM_STEPS as u32
}

fn retrieval_off() -> String {
    "off".into()
}

pub(super) fn spec_to_row(s: &JobSpec) -> (String, Vec<u8>) {
    let doc = SpecDoc {
        category: s.category.clone(),
        w_pc: s.w_pc,
        w_pen: s.w_pen,
        w_mob: s.w_mob,
        n_g_t: Some(s.n_g),
        n_g: None,
        tau: s.tau,
        guidance_max_step: s.guidance_max_step,
        refine_steps: s.refine_steps,
        refine_physics_steps: s.refine_physics_steps,
        sampler: s.sampler.name().to_string(),
        eta: s.sampler.eta(),
        steps: s.steps,
        seed: s.seed,
        samples: s.samples,
        deadline_seconds: s.deadline_seconds,
        preview_every: s.preview_every,
        resolution: s.resolution,
        retrieval: s.retrieval.as_str().to_string(),
        category_guidance: s.category_guidance,
        category_guidance_below: s.category_guidance_below,
        joint_motion: s.joint_motion.as_str().to_string(),
        cameras: s.cameras.clone(),
        w_free: s.w_free,
        repair: s.repair.as_str().to_string(),
        scale: s.scale,
        frame: s.frame.map(|f| (f.up.into(), f.yaw, f.translation.into())),
    };
    let mut blob = Vec::with_capacity(s.points.len() * 12);
    for p in &s.points {
        for c in p {
            blob.extend_from_slice(&c.to_le_bytes());
        }
    }
    // Serialising plain numbers and strings cannot fail.
    (serde_json::to_string(&doc).unwrap_or_default(), blob)
}

pub(super) fn spec_from_row(id: &str, json: &str, blob: &[u8]) -> Result<JobSpec, StoreError> {
    let corrupt = |detail: String| StoreError::Corrupt {
        id: id.to_string(),
        detail,
    };
    let d: SpecDoc = serde_json::from_str(json).map_err(|e| corrupt(e.to_string()))?;
    if !blob.len().is_multiple_of(12) {
        return Err(corrupt(format!("points blob of {} bytes", blob.len())));
    }
    let f = |c: &[u8]| f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    let sampler = match d.sampler.as_str() {
        "ddpm" => Sampler::Ddpm,
        "ddim" => Sampler::Ddim { eta: d.eta },
        other => return Err(corrupt(format!("unknown sampler {other:?}"))),
    };
    let retrieval = Retrieval::parse(&d.retrieval)
        .ok_or_else(|| corrupt(format!("unknown retrieval {:?}", d.retrieval)))?;
    let joint_motion = JointMotion::parse(&d.joint_motion)
        .ok_or_else(|| corrupt(format!("unknown joint motion {:?}", d.joint_motion)))?;
    let repair = RepairMode::parse(&d.repair)
        .ok_or_else(|| corrupt(format!("unknown repair mode {:?}", d.repair)))?;
    let n_g = match (d.n_g_t, d.n_g) {
        (Some(t), _) => t,
        (None, Some(last)) => threshold_of_final_steps(d.steps, last),
        (None, None) => return Err(corrupt("no n_g".into())),
    };
    Ok(JobSpec {
        points: blob
            .chunks_exact(12)
            .map(|c| [f(&c[0..4]), f(&c[4..8]), f(&c[8..12])])
            .collect(),
        category: d.category,
        w_pc: d.w_pc,
        w_pen: d.w_pen,
        w_mob: d.w_mob,
        n_g,
        tau: d.tau,
        guidance_max_step: d.guidance_max_step,
        refine_steps: d.refine_steps,
        refine_physics_steps: d.refine_physics_steps,
        sampler,
        steps: d.steps,
        seed: d.seed,
        samples: d.samples,
        deadline_seconds: d.deadline_seconds,
        preview_every: d.preview_every,
        resolution: d.resolution,
        retrieval,
        category_guidance: d.category_guidance,
        category_guidance_below: d.category_guidance_below,
        joint_motion,
        cameras: d.cameras,
        w_free: d.w_free,
        repair,
        scale: d.scale,
        frame: d
            .frame
            .and_then(|(up, yaw, t)| crate::frame::ScanFrame::new(up, yaw, t).ok()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_stored_before_newer_options_keep_the_behaviour_they_were_accepted_with() {
        // A spec row as the first service release wrote it (no retrieval, category guidance,
        // guidance limit or joint motion): it still runs, as it was accepted.
        let json = r#"{"category":[1,"Door"],"w_pc":1.0,"w_pen":1.0,"w_mob":1.0,"n_g":200,
            "tau":0.1,"sampler":"ddim","steps":200,"seed":7,"samples":1,
            "deadline_seconds":600.0,"preview_every":0,"resolution":32}"#;
        let spec = spec_from_row("j", json, &[0u8; 24]).unwrap();
        assert_eq!(spec.points.len(), 2);
        assert_eq!(spec.retrieval, Retrieval::Off);
        assert_eq!(spec.category_guidance, 0.0);
        assert_eq!(spec.category_guidance_below, 1000);
        assert_eq!(spec.joint_motion, JointMotion::Screw);
        assert_eq!(spec.refine_physics_steps, 0);
        // n_g was then a count of final steps: the last 200 of 200 steps guided is every step
        // (t < 1000); the threshold read for any count guides exactly that many steps.
        assert_eq!(spec.n_g, 1000);
        for last in [0, 1, 7, 100, 200] {
            let old = json.replace(r#""n_g":200"#, &format!(r#""n_g":{last}"#));
            let t = spec_from_row("j", &old, &[]).unwrap().n_g as usize;
            let guided = timesteps(NUM_STEPS, 200).into_iter().filter(|&s| s < t);
            assert_eq!(guided.count(), last as usize, "{last}: t < {t}");
        }
        // And a spec round-trips through its row unchanged.
        let (json, blob) = spec_to_row(&JobSpec {
            refine_physics_steps: 7,
            ..spec.clone()
        });
        let back = spec_from_row("j", &json, &blob).unwrap();
        assert_eq!(
            back,
            JobSpec {
                refine_physics_steps: 7,
                ..spec
            }
        );
        assert_eq!(back.category_guidance_below, 1000);
        assert_eq!(back.seed, 7);
        let corrupt = spec_from_row("j", &json, &[0u8; 5])
            .unwrap_err()
            .to_string();
        assert!(corrupt.contains("5 bytes"), "{corrupt}");
    }

    #[test]
    fn rows_stored_before_cameras_and_repair_load_without_them() {
        // A spec row as the service wrote it before cameras, w_free and repair: it was accepted
        // by a pipeline without repair or ℓ_free, and loads as such.
        let json = r#"{"category":null,"w_pc":15.0,"w_pen":2.0,"w_mob":2.0,"n_g":100,
            "tau":1000.0,"guidance_max_step":0.02,"refine_steps":30,"refine_physics_steps":0,
            "sampler":"ddim","eta":0.0,"steps":200,"seed":3,"samples":1,
            "deadline_seconds":3600.0,"preview_every":0,"resolution":32,"retrieval":"empty",
            "category_guidance":0.0,"category_guidance_below":1000,"joint_motion":"dominant"}"#;
        let spec = spec_from_row("j", json, &[0u8; 24]).unwrap();
        assert_eq!(spec.repair, RepairMode::Off);
        assert!(spec.cameras.is_empty());
        assert_eq!(spec.w_free, 0.0);
        assert_eq!(spec.joint_motion, JointMotion::Dominant);
        // The new fields round-trip exactly (f32 cameras through JSON included).
        let with = JobSpec {
            cameras: vec![[0.1, -2.5, 1.0e-3], [3.0, 0.0, 0.7]],
            w_free: 15.0,
            repair: RepairMode::On,
            ..spec
        };
        let (json, blob) = spec_to_row(&with);
        assert_eq!(spec_from_row("j", &json, &blob).unwrap(), with);
        let bad = json.replace(r#""repair":"on""#, r#""repair":"maybe""#);
        assert_ne!(bad, json);
        let e = spec_from_row("j", &bad, &blob).unwrap_err().to_string();
        assert!(e.contains("unknown repair mode \"maybe\""), "{e}");
    }
}
