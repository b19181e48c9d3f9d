//! The one function that turns a [`JobSpec`] into artefacts by driving the engine.
//!
//! Why it exists: everything engine-facing of a job lives in [`run_job`]; the scheduler, store
//! and transports never touch the engine. It runs on the caller's (the service's dedicated)
//! rayon pool, checks the caller's stop condition at every reverse step and between phases,
//! and reports progress with an ETA, the guided step's loss values and, every
//! `preview_every` steps, a light x̂₀ preview (part boxes and joints).
//!
//! Guidance (PhysNAP, method.md §8): the job's cloud and weights become a
//! [`GuidanceOptions`] (n_g is the engine's: steps with diffusion time t < n_g are guided),
//! the trained shape decoder is the part SDF the losses
//! query, and the spec's sampler and step count pick the engine's reverse-step rule. All
//! weights 0 samples unguided (plain NAP). The job's cameras add ℓ_free at `w_free`; with
//! `repair` on (the default) the engine repairs the joints and removes the parts the scan does
//! not allow (empty, in the cameras' free space, floating).
//!
//! Best-of-N: each sample `i` (seed + i) runs on its own; a sample that diverges
//! ([`EngineError::Diverged`]) is recorded and skipped, and the others are ranked by the score
//! of `eval::rank` (the CLI's: D_pc / scan diagonal + free-space share + attachment gap /
//! object diagonal + O_mesh, ascending; samples without a mesh last). The best is exported
//! through `export::artefacts` as `model.glb`, `model.xml` (MJCF), `robot.zip` (URDF + MJCF +
//! meshes) and `object.json`; `ranking.json` (`physnap.job_ranking/v1`) lists
//! every sample with index, seed, score and its terms, D_pc, O_mesh (surface buried in another
//! part), its joint repairs (count) and removed parts, whether it diverged
//! (and why) and which one was exported. If every sample diverges the job fails with
//! [`RunError::AllDiverged`].

use std::ops::ControlFlow;
use std::time::Instant;

use crate::engine::EngineError;
use crate::engine::generate::{GenerateRequest, Generated, PartShapes, generate_with};
use crate::engine::guidance::{GuidanceLosses, GuidanceOptions, SdfField};
use crate::engine::sample::step_events;
use crate::engine::schedule::Schedule;
use crate::eval::rank::{RankTerms, sample_terms};
use crate::export::{ExportError, ExportOptions, artefacts, collision};
use crate::graph::{ProjectOptions, project};
use crate::io::manifest::LoadedModels;
use crate::mesh::MeshingOptions;
use crate::model::shape_prior::LatentSdfDecoder;
use crate::object::ArticulatedObject;

use super::spec::JobSpec;

/// The loaded weights and the schedule, shared by all jobs.
pub struct Models {
    /// Denoiser, shape prior and manifest.
    pub loaded: LoadedModels,
    /// The DDPM schedule.
    pub schedule: Schedule,
}

/// Phase of a running job.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Reverse diffusion.
    Denoising,
    /// Marching cubes on the decoded part shapes.
    Meshing,
    /// GLB / URDF / JSON writing.
    Exporting,
}

impl Phase {
    /// Wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Denoising => "denoising",
            Phase::Meshing => "meshing",
            Phase::Exporting => "exporting",
        }
    }
}

/// A part box of a preview (object frame, metres).
#[derive(Debug, Clone, PartialEq)]
pub struct PreviewPart {
    /// Part name.
    pub name: String,
    /// Box centre.
    pub center: [f64; 3],
    /// Box half-extents.
    pub half_extents: [f64; 3],
}

/// A joint of a preview.
#[derive(Debug, Clone, PartialEq)]
pub struct PreviewJoint {
    /// Parent part index.
    pub parent: usize,
    /// Child part index.
    pub child: usize,
    /// `revolute`, `prismatic`, `screw` or `fixed`.
    pub kind: &'static str,
    /// Unit axis.
    pub axis: [f64; 3],
    /// A point on the axis.
    pub origin: [f64; 3],
}

/// The projected x̂₀ of a step: where the sample is heading.
#[derive(Debug, Clone, PartialEq)]
pub struct Preview {
    /// Parts.
    pub parts: Vec<PreviewPart>,
    /// Joints.
    pub joints: Vec<PreviewJoint>,
}

/// Progress of a job.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// Current phase.
    pub phase: Phase,
    /// Sample being drawn (0-based).
    pub sample: u32,
    /// Samples in the job.
    pub samples: u32,
    /// 1-based step within the sample.
    pub step: u32,
    /// Steps per sample.
    pub total_steps: u32,
    /// Diffusion time index of the step.
    pub t: u32,
    /// Estimated seconds left (from the mean step time so far).
    pub eta_seconds: Option<f64>,
    /// x̂₀ preview, every `preview_every` steps.
    pub preview: Option<Preview>,
    /// Loss values of this step (ℓ_pc, ℓ_pen, ℓ_mob, ℓ_free, weighted total), guided steps only.
    pub guidance: Option<GuidanceLosses>,
}

/// What a successful job produced: the artefacts' bytes, in a fixed order.
#[derive(Debug, Clone)]
pub struct JobOutput {
    /// `(file name, bytes)`: `model.glb`, `model.xml`, `robot.zip`, `object.json`,
    /// `ranking.json`.
    pub files: Vec<(String, Vec<u8>)>,
    /// Index of the exported sample.
    pub chosen_sample: u32,
}

/// Why a run ended without output.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The stop condition fired (cancellation or deadline).
    #[error("stopped: {0}")]
    Stopped(String),
    /// The engine failed (projection, meshing, invalid options).
    #[error("engine: {0}")]
    Engine(EngineError),
    /// Every sample of the job diverged under guidance.
    #[error(
        "all {samples} samples diverged under guidance (first: {first}); lower the guidance weights (w_pc, w_pen, w_mob, w_free), n_g, or set guidance_max_step"
    )]
    AllDiverged {
        /// Samples in the job.
        samples: u32,
        /// The first sample's divergence.
        first: String,
    },
    /// Export failed.
    #[error("export: {0}")]
    Export(#[from] ExportError),
}

impl RunError {
    /// Machine-readable kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            RunError::Stopped(_) => "stopped",
            RunError::Engine(e) => e.error_type(),
            RunError::AllDiverged { .. } => "diverged",
            RunError::Export(e) => e.error_type(),
        }
    }
}

fn preview_of(obj: &ArticulatedObject) -> Preview {
    let v = |x: &nalgebra::Vector3<f64>| [x.x, x.y, x.z];
    Preview {
        parts: obj
            .parts
            .iter()
            .map(|p| PreviewPart {
                name: p.name.clone(),
                center: v(&p.center),
                half_extents: v(&p.half_extents),
            })
            .collect(),
        joints: obj
            .joints
            .iter()
            .map(|j| PreviewJoint {
                parent: j.parent,
                child: j.child,
                kind: j.kind.as_str(),
                axis: v(&j.axis),
                origin: [j.origin.x, j.origin.y, j.origin.z],
            })
            .collect(),
    }
}

/// The engine's guidance of a spec: None when no loss guides it and it has no camera (a camera
/// alone still tells the part removal which space the scan saw through).
pub fn guidance_of(spec: &JobSpec) -> Option<GuidanceOptions> {
    (spec.guided() || !spec.cameras.is_empty()).then(|| {
        GuidanceOptions {
            points: spec.points.clone(),
            w_pc: spec.w_pc,
            w_pen: spec.w_pen,
            w_mob: spec.w_mob,
            cameras: Vec::new(),
            w_free: 0.0,
            steps: spec.n_g as usize,
            tau: spec.tau,
            max_step: spec.guidance_max_step,
            refine_steps: spec.refine_steps as usize,
            refine_physics_steps: spec.refine_physics_steps as usize,
        }
        .with_cameras(spec.cameras.clone(), Some(spec.w_free))
    })
}

/// One row of `ranking.json`.
struct Ranked {
    index: usize,
    seed: u64,
    d_pc: f64,
    /// O_mesh: share of the part surface buried in another part (NaN when diverged).
    o_mesh: f64,
    /// The ranking score (NaN when diverged).
    score: f64,
    /// The ranking terms as `ranking.json` lists them (None when diverged).
    terms: Option<serde_json::Value>,
    diverged: Option<String>,
    /// Parts that took their nearest codebook shape.
    retrieved: Vec<usize>,
    /// Joint repairs made (object.json lists the exported sample's).
    repairs: usize,
    /// Parts removed: `{part, reason, detail}` each.
    removed: Vec<serde_json::Value>,
}

fn ranking_json(spec: &JobSpec, guidance: &Option<GuidanceOptions>, rows: &[Ranked]) -> Vec<u8> {
    let num = |v: f64| {
        if v.is_finite() {
            serde_json::json!(v)
        } else {
            serde_json::Value::Null
        }
    };
    let best = rows.iter().find(|r| r.diverged.is_none()).map(|r| r.index);
    let doc = serde_json::json!({
        "format": "physnap.job_ranking/v1",
        "ranked_by": "score = D_pc / scan diagonal + free-space share + attachment gap / object diagonal + O_mesh + sim contact depth / object diagonal (ascending; diverged samples last)",
        "guided": spec.guided(),
        "guidance": guidance.as_ref().map(|g| serde_json::json!({
            "w_pc": g.w_pc, "w_pen": g.w_pen, "w_mob": g.w_mob, "w_free": g.w_free,
            "cameras": g.cameras,
            "n_g": g.steps, "tau": g.tau,
            "max_step": g.max_step, "refine_steps": g.refine_steps,
            "refine_physics_steps": g.refine_physics_steps,
        })),
        "sampler": spec.sampler.name(), "eta": spec.sampler.eta(), "steps": spec.steps,
        "retrieval": spec.retrieval.as_str(),
        "category_guidance": spec.category_guidance,
        "category_guidance_below": spec.category_guidance_below,
        "joint_motion": spec.joint_motion.as_str(),
        "repair": spec.repair.as_str(),
        "frame": spec.frame.map(|f| serde_json::json!({
            "mode": "auto",
            "up": <[f64; 3]>::from(f.up),
            "yaw_degrees": f.yaw.to_degrees(),
            "floor": -f.translation.z,
            "translation": <[f64; 3]>::from(f.translation),
        })),
        "best": best,
        "samples": rows.iter().enumerate().map(|(rank, r)| serde_json::json!({
            "rank": rank + 1,
            "index": r.index,
            "seed": r.seed,
            "score": num(r.score),
            "terms": r.terms,
            "d_pc": num(r.d_pc),
            "o_mesh": num(r.o_mesh),
            "diverged": r.diverged.is_some(),
            "retrieved_parts": r.retrieved,
            "repairs": r.repairs,
            "removed": r.removed,
            "error": r.diverged,
            "exported": Some(r.index) == best,
        })).collect::<Vec<_>>(),
    });
    // Serialising plain numbers and strings cannot fail.
    (serde_json::to_string_pretty(&doc).unwrap_or_default() + "\n").into_bytes()
}

/// Run one job on the current rayon pool. `stop` is polled every step and between phases; when
/// it returns a reason the run ends with [`RunError::Stopped`].
pub fn run_job(
    models: &Models,
    spec: &JobSpec,
    progress: &mut dyn FnMut(&Progress),
    stop: &dyn Fn() -> Option<String>,
) -> Result<JobOutput, RunError> {
    let m = &models.loaded;
    let scales = &m.manifest.feature_scales;
    let guidance = guidance_of(spec);
    let req = GenerateRequest {
        seed: spec.seed,
        samples: 1,
        category: spec.category.as_ref().map(|c| c.0),
        category_name: spec.category.as_ref().map(|c| c.1.clone()),
        meshing: MeshingOptions {
            resolution: spec.resolution as usize,
        },
        preview_every: spec.preview_every as usize,
        guidance: guidance.clone(),
        sampler: spec.sampler,
        steps: spec.steps as usize,
        retrieval: spec.retrieval,
        category_guidance: spec.category_guidance,
        category_guidance_below: Some(spec.category_guidance_below as usize),
        joint_motion: spec.joint_motion,
        repair: spec.repair,
        scale: spec.scale,
        frame: spec.frame,
    };
    // The samples come out canonical: they are ranked against the scan moved there.
    let ranked_against = crate::engine::generate::canonical_guidance(&req);
    let (rank_points, rank_cameras) = match &ranked_against {
        Some(g) => (g.points.clone(), g.cameras.clone()),
        None => (spec.points.clone(), spec.cameras.clone()),
    };
    let decoder = LatentSdfDecoder::new(&m.shape_prior.decoder);
    let started = Instant::now();
    let per_sample = step_events(
        models.schedule.len(),
        spec.steps as usize,
        guidance.as_ref(),
    );
    let total_all = spec.samples as usize * per_sample;
    let mut done_samples: Vec<Generated> = Vec::new();
    let mut diverged: Vec<(usize, u64, String)> = Vec::new();
    for i in 0..spec.samples as usize {
        let one = GenerateRequest {
            seed: spec.seed.wrapping_add(i as u64),
            ..req.clone()
        };
        let mut on_step = |e: &crate::engine::generate::GenerateEvent| {
            if let Some(reason) = stop() {
                return ControlFlow::Break(reason);
            }
            let done = i * e.step.total + e.step.step;
            let eta = (done > 0).then(|| {
                started.elapsed().as_secs_f64() / done as f64
                    * (total_all - done.min(total_all)) as f64
            });
            let preview = e.step.x0_preview.as_ref().and_then(|g| {
                let raw = g.first()?.unscaled(scales);
                project(&raw, &ProjectOptions::default())
                    .ok()
                    .map(|o| preview_of(&o))
            });
            progress(&Progress {
                phase: if e.step.step == e.step.total {
                    Phase::Meshing
                } else {
                    Phase::Denoising
                },
                sample: i as u32,
                samples: spec.samples,
                step: e.step.step as u32,
                total_steps: e.step.total as u32,
                t: e.step.t as u32,
                eta_seconds: eta,
                preview,
                guidance: e.step.guidance,
            });
            ControlFlow::Continue(())
        };
        let shapes = PartShapes {
            decoder: &decoder,
            field: Some(&decoder as &dyn SdfField),
            codebook: m.codebook.as_ref(),
        };
        let r = generate_with(
            &m.denoiser,
            &shapes,
            scales,
            &models.schedule,
            &one,
            &mut on_step,
        );
        match r {
            Ok(mut out) if !out.is_empty() => {
                let mut g = out.remove(0);
                g.index = i;
                g.object.name = format!("sample_{i:03}");
                done_samples.push(g);
            }
            Ok(_) => {
                return Err(RunError::Engine(EngineError::Invalid(
                    crate::error::Invalid {
                        field: "samples".into(),
                        limit: "at least 1".into(),
                        value: "0".into(),
                    },
                )));
            }
            Err(EngineError::Stopped { reason, .. }) => return Err(RunError::Stopped(reason)),
            Err(e @ EngineError::Diverged { .. }) => {
                diverged.push((i, one.seed, e.to_string()));
            }
            Err(other) => return Err(RunError::Engine(other)),
        }
        if let Some(reason) = stop() {
            return Err(RunError::Stopped(reason));
        }
    }
    if done_samples.is_empty() {
        return Err(RunError::AllDiverged {
            samples: spec.samples,
            first: diverged.first().map(|d| d.2.clone()).unwrap_or_default(),
        });
    }
    // Best-of-N by the ranking score (NaN, i.e. no mesh, ranks last; ties by index).
    // `done_samples` is in index order, so ties stay in index order.
    let scored: Vec<(RankTerms, Generated)> = done_samples
        .into_iter()
        .map(|g| {
            let t = sample_terms(&g.object, &g.meshes, &rank_points, &rank_cameras, g.seed);
            (t, g)
        })
        .collect();
    let mut ranked = crate::eval::rank::ranked(scored, |s| s.0.score());
    let mut rows: Vec<Ranked> = ranked
        .iter()
        .map(|(t, g)| Ranked {
            index: g.index,
            seed: g.seed,
            d_pc: t.d_pc,
            o_mesh: t.o_mesh,
            score: t.score(),
            terms: Some(crate::io::verdict::terms_json(&g.object, t)),
            diverged: None,
            retrieved: g.retrieved.clone(),
            repairs: g.repairs.len(),
            removed: g
                .removed
                .iter()
                .map(|r| {
                    serde_json::json!({
                        "part": r.part, "reason": r.reason.as_str(), "detail": r.detail,
                    })
                })
                .collect(),
        })
        .collect();
    rows.extend(diverged.into_iter().map(|(index, seed, e)| Ranked {
        index,
        seed,
        d_pc: f64::NAN,
        o_mesh: f64::NAN,
        score: f64::NAN,
        terms: None,
        diverged: Some(e),
        retrieved: Vec::new(),
        repairs: 0,
        removed: Vec::new(),
    }));
    let ranking = ranking_json(spec, &guidance, &rows);
    let chosen = ranked.swap_remove(0).1;
    let n = per_sample as u32;
    progress(&Progress {
        phase: Phase::Exporting,
        sample: chosen.index as u32,
        samples: spec.samples,
        step: n,
        total_steps: n,
        t: 0,
        eta_seconds: Some(0.0),
        preview: None,
        guidance: None,
    });
    let opts = ExportOptions {
        meshing: req.meshing,
        frame: spec.frame,
        ..Default::default()
    };
    let mut art = artefacts(
        &chosen.object,
        &chosen.meshes,
        &collision::pieces(&chosen.object, &chosen.meshes, &opts.collision),
        &chosen.repairs,
        &opts,
    )?;
    for note in &art.notes {
        tracing::info!(sample = chosen.index, "export: {note}");
    }
    let mut files = Vec::with_capacity(5);
    for name in ["model.glb", "model.xml", "robot.zip", "object.json"] {
        // `artefacts` always builds these four; a missing one would be a bug there.
        let bytes = art.take(name).unwrap_or_default();
        files.push((name.to_string(), bytes));
    }
    files.push(("ranking.json".into(), ranking));
    Ok(JobOutput {
        files,
        chosen_sample: chosen.index as u32,
    })
}
