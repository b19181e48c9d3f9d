//! Generation end to end: sample graphs, project them to objects, mesh their parts.
//!
//! Why it exists: the CLI's `generate`, the service and the evaluation all need "seed in,
//! articulated objects with meshes out"; this is that pipeline, transport-free. Sample `i` of a
//! request is drawn with seed `seed + i` in its own batch-of-one run, so sample i is the same
//! whether 1 or N samples were asked for.

use std::ops::ControlFlow;

use super::EngineError;
use super::guidance::{GuidanceOptions, SdfField};
use super::sample::{GuidanceContext, SampleRequest, Sampler, StepEvent, sample_guided};
use super::schedule::Schedule;
use crate::graph::{FeatureScales, GraphTensor, ProjectOptions, project};
use crate::mesh::{MeshingOptions, TriMesh};
use crate::model::denoiser::Denoiser;
use crate::object::ArticulatedObject;
use crate::shape::LatentDecoder;

/// What to generate.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GenerateRequest {
    /// Seed of sample 0 (sample i uses seed + i).
    pub seed: u64,
    /// Number of samples.
    pub samples: usize,
    /// Category index, or None for unconditional generation.
    pub category: Option<usize>,
    /// Category name written into the objects.
    pub category_name: Option<String>,
    /// Meshing settings.
    pub meshing: MeshingOptions,
    /// Attach x̂₀ previews to every this many steps' events (0: never); see
    /// [`SampleRequest::preview_every`].
    pub preview_every: usize,
    /// PhysNAP loss guidance (None: plain NAP sampling); needs [`generate_with`] and a field.
    pub guidance: Option<GuidanceOptions>,
    /// Reverse-step rule.
    pub sampler: Sampler,
    /// Reverse steps (0: all of the schedule).
    pub steps: usize,
}

/// One generated sample.
#[derive(Debug, Clone)]
pub struct Generated {
    /// Sample index within the request.
    pub index: usize,
    /// Seed it was drawn with.
    pub seed: u64,
    /// The raw (unscaled) graph the model produced.
    pub raw: GraphTensor,
    /// The projected object (latent part shapes).
    pub object: ArticulatedObject,
    /// Part meshes, object frame at rest.
    pub meshes: Vec<TriMesh>,
}

/// Progress of a generation request.
#[derive(Debug, Clone, PartialEq)]
pub struct GenerateEvent {
    /// Sample being drawn.
    pub sample: usize,
    /// Its diffusion step.
    pub step: StepEvent,
}

/// Generate `req.samples` objects (unguided; a request with active guidance is refused with
/// an error naming `guidance` — use [`generate_with`]).
pub fn generate(
    denoiser: &Denoiser,
    decoder: &dyn LatentDecoder,
    scales: &FeatureScales,
    schedule: &Schedule,
    req: &GenerateRequest,
    on_step: &mut dyn FnMut(&GenerateEvent) -> ControlFlow<String>,
) -> Result<Vec<Generated>, EngineError> {
    generate_with(denoiser, decoder, None, scales, schedule, req, on_step)
}

/// Generate `req.samples` objects; `field` is the part SDF the guidance losses query (the
/// trained shape decoder, e.g. the same `LatentSdfDecoder` as `decoder`), required when
/// `req.guidance` has a positive weight.
pub fn generate_with(
    denoiser: &Denoiser,
    decoder: &dyn LatentDecoder,
    field: Option<&dyn SdfField>,
    scales: &FeatureScales,
    schedule: &Schedule,
    req: &GenerateRequest,
    on_step: &mut dyn FnMut(&GenerateEvent) -> ControlFlow<String>,
) -> Result<Vec<Generated>, EngineError> {
    let device = crate::model::cpu();
    let mut out = Vec::with_capacity(req.samples);
    for i in 0..req.samples {
        let seed = req.seed.wrapping_add(i as u64);
        let graphs = sample_guided(
            denoiser,
            schedule,
            &SampleRequest {
                seed,
                batch: 1,
                category: req.category,
                preview_every: req.preview_every,
                guidance: req.guidance.clone(),
                sampler: req.sampler,
                steps: req.steps,
            },
            field.map(|field| GuidanceContext { field, scales }),
            &device,
            &mut |s| {
                on_step(&GenerateEvent {
                    sample: i,
                    step: s.clone(),
                })
            },
        )?;
        let raw = graphs[0].unscaled(scales);
        let object = project(
            &raw,
            &ProjectOptions {
                name: format!("sample_{i:03}"),
                category: req.category_name.clone(),
                ..Default::default()
            },
        )
        .map_err(|e| EngineError::Invalid {
            field: "sample".into(),
            limit: "a projectable graph".into(),
            value: e.to_string(),
        })?;
        let meshes =
            crate::mesh::mesh_parts(&object, Some(decoder), &req.meshing).map_err(|e| {
                EngineError::Invalid {
                    field: "meshing".into(),
                    limit: "valid meshing options".into(),
                    value: e.to_string(),
                }
            })?;
        out.push(Generated {
            index: i,
            seed,
            raw,
            object,
            meshes,
        });
    }
    Ok(out)
}
