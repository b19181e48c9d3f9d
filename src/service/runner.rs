//! The one function that turns a [`JobSpec`] into artefacts by driving the engine.
//!
//! Why it exists: everything engine-facing of a job lives in [`run_job`], so the guidance work
//! (point-cloud, penetration and mobility losses, strided samplers) plugs in by editing this
//! function only; the scheduler, store and transports never touch the engine. It runs on the
//! caller's (the service's dedicated) rayon pool, checks the caller's stop condition at every
//! diffusion step and between phases, and reports progress with an ETA and, every
//! `preview_every` steps, a light x̂₀ preview (part boxes and joints).
//!
//! **Not yet guided.** The engine has no guidance terms yet, so the point cloud and the loss
//! weights w_pc, w_pen, w_mob, n_g and τ are validated and stored but do not influence the
//! sample: generation is unconditional on the cloud (category-conditioned when a category is
//! given). Best-of-N therefore has nothing to rank by, and the first sample is exported.

use std::ops::ControlFlow;
use std::time::Instant;

use crate::engine::EngineError;
use crate::engine::generate::{GenerateRequest, generate};
use crate::engine::schedule::Schedule;
use crate::export::{ExportError, ExportOptions, glb, urdf, zip_bundle};
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
}

/// What a successful job produced: the artefacts' bytes, in a fixed order.
#[derive(Debug, Clone)]
pub struct JobOutput {
    /// `(file name, bytes)`: `model.glb`, `robot.zip`, `object.json`.
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
    /// The engine failed (divergence, projection).
    #[error("engine: {0}")]
    Engine(EngineError),
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
    // `..Default::default()` on purpose: the guidance work adds fields to GenerateRequest, and
    // this literal must keep compiling (and pick their defaults) until it sets them here.
    #[allow(clippy::needless_update)]
    let req = GenerateRequest {
        seed: spec.seed,
        samples: spec.samples as usize,
        category: spec.category.as_ref().map(|c| c.0),
        category_name: spec.category.as_ref().map(|c| c.1.clone()),
        meshing: MeshingOptions {
            resolution: spec.resolution as usize,
        },
        preview_every: spec.preview_every as usize,
        ..Default::default()
    };
    let decoder = LatentSdfDecoder::new(&m.shape_prior.decoder);
    let started = Instant::now();
    let total_all = spec.samples as usize * models.schedule.len();
    let mut on_step = |e: &crate::engine::generate::GenerateEvent| {
        if let Some(reason) = stop() {
            return ControlFlow::Break(reason);
        }
        let done = e.sample * e.step.total + e.step.step;
        let eta = (done > 0).then(|| {
            started.elapsed().as_secs_f64() / done as f64 * (total_all - done.min(total_all)) as f64
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
            sample: e.sample as u32,
            samples: spec.samples,
            step: e.step.step as u32,
            total_steps: e.step.total as u32,
            t: e.step.t as u32,
            eta_seconds: eta,
            preview,
        });
        ControlFlow::Continue(())
    };
    let results = generate(
        &m.denoiser,
        &decoder,
        scales,
        &models.schedule,
        &req,
        &mut on_step,
    )
    .map_err(|e| match e {
        EngineError::Stopped { reason, .. } => RunError::Stopped(reason),
        other => RunError::Engine(other),
    })?;
    if let Some(reason) = stop() {
        return Err(RunError::Stopped(reason));
    }
    // Best-of-N: without guidance losses there is nothing to rank by; take sample 0.
    let chosen = results.into_iter().next().ok_or_else(|| {
        RunError::Engine(EngineError::Invalid {
            field: "samples".into(),
            limit: "at least 1".into(),
            value: "0".into(),
        })
    })?;
    let n = models.schedule.len() as u32;
    progress(&Progress {
        phase: Phase::Exporting,
        sample: chosen.index as u32,
        samples: spec.samples,
        step: n,
        total_steps: n,
        t: 0,
        eta_seconds: Some(0.0),
        preview: None,
    });
    let opts = ExportOptions {
        meshing: req.meshing,
        ..Default::default()
    };
    let glb = glb::build(&chosen.object, &chosen.meshes, &opts)?;
    let bundle = urdf::build(&chosen.object, &chosen.meshes, &opts);
    let zip = zip_bundle(&bundle)?;
    let json = crate::io::object_json::to_string(&chosen.object).into_bytes();
    Ok(JobOutput {
        files: vec![
            ("model.glb".into(), glb),
            ("robot.zip".into(), zip),
            ("object.json".into(), json),
        ],
        chosen_sample: chosen.index as u32,
    })
}
