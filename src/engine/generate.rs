//! Generation end to end: sample graphs, project them to objects, mesh their parts.
//!
//! Why it exists: the CLI's `generate`, the service and the evaluation all need "seed in,
//! articulated objects with meshes out"; this is that pipeline, transport-free. Sample `i` of a
//! request is drawn with seed `seed + i` in its own batch-of-one run, so sample i is the same
//! whether 1 or N samples were asked for.
//!
//! Retrieval (method.md §5.9, on codes): with [`Retrieval::Empty`] a part whose decoded shape
//! meshes empty gets the nearest training code of the weights' codebook instead (1-NN,
//! Euclidean, raw codes) and is meshed again; [`Retrieval::All`] does that for every latent
//! part (NAP's retrieval variant); [`Retrieval::Category`] does it for every latent part of a
//! category-conditioned sample, searching only the codes of that category's training objects
//! (physnap's, not in the paper: the requested category then also decides the part shapes).
//! The replaced parts are listed in [`Generated::retrieved`]; `raw` stays the graph the model
//! produced, `object` carries the retrieved codes.
//!
//! Joint motions: with [`JointMotion::Dominant`] the projection keeps only each joint's wider
//! range, compared in units of the range channels' feature scales ([`range_units`]); the
//! engine's default is NAP's (every joint a screw), the CLI and the service default to
//! dominant.
//!
//! Scale ([`GenerateRequest::scale`], physnap's): the prior draws objects of its training
//! sizes, so a scan of a much smaller or larger object was wrapped in an object of the usual
//! size. With a scale s the scan (and cameras) are multiplied by s about the origin (the floor
//! stays at z = 0), the sample is drawn and projected in that frame, and the object is divided
//! by s before repair and meshing (latent shapes live in the box's normalised frame, so only
//! boxes, centres, origins and slide ranges change).
//!
//! Frame ([`GenerateRequest::frame`], physnap's): a scan in the user's frame is moved into the
//! canonical frame (+Z up, front −X, floor z = 0) by its [`ScanFrame`] before the scale; the
//! sample is drawn, projected, repaired and meshed there, and the exporters put it back on
//! the scan (`crate::frame`; the frame itself is estimated by [`super::frame::estimate`]).
//!
//! Repair ([`RepairMode::On`], physnap's, not NAP's; the CLI's and the service's default): after
//! projection the joints are repaired (`graph::repair`: attach, snap, pivot on an edge or the
//! centre line), and after meshing the leaf parts the scan does not allow are removed
//! ([`super::prune`]: empty, in the cameras' free space, floating). Both are listed in
//! [`Generated::repairs`] and [`Generated::removed`]. The engine's default is off: the raw
//! projection, byte for byte.

use std::ops::ControlFlow;

use super::EngineError;
use super::free_space::FreeSpace;
use super::guidance::{GuidanceOptions, SdfField};
use super::prune::{Removed, prune};
use super::sample::{GuidanceContext, SampleRequest, Sampler, StepEvent, sample_guided};
use super::schedule::Schedule;
use crate::frame::ScanFrame;
use crate::graph::repair::{Repair, repair};
use crate::graph::{FeatureScales, GraphTensor, ProjectOptions, project};
use crate::mesh::{MeshingOptions, TriMesh, part_mesh};
use crate::model::codebook::Codebook;
use crate::model::denoiser::Denoiser;
use crate::object::ArticulatedObject;
use crate::shape::{LatentDecoder, PartShape};

/// Which generated part shapes are replaced by their nearest codebook code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Retrieval {
    /// Keep every decoded shape (the paper's SDF-extracted meshes).
    #[default]
    Off,
    /// Replace only shapes that mesh empty.
    Empty,
    /// Replace every latent shape (NAP's retrieval variant).
    All,
    /// Replace every latent shape by the nearest code of the requested category's training
    /// parts (needs a category and a codebook whose codes carry categories).
    Category,
}

impl Retrieval {
    /// Wire / flag name.
    pub fn as_str(self) -> &'static str {
        match self {
            Retrieval::Off => "off",
            Retrieval::Empty => "empty",
            Retrieval::All => "all",
            Retrieval::Category => "category",
        }
    }

    /// What `auto` (the CLI's and the service's default) means for weights with or without a
    /// retrieval codebook: replace the shapes that mesh empty when there is one, else off.
    pub fn auto(has_codebook: bool) -> Self {
        if has_codebook {
            Retrieval::Empty
        } else {
            Retrieval::Off
        }
    }

    /// The mode for a sample drawn without a category: `Category` becomes `Empty` (the
    /// evaluations' mixed runs use it), the others stay.
    pub fn without_category(self) -> Self {
        match self {
            Retrieval::Category => Retrieval::Empty,
            r => r,
        }
    }

    /// Parse a wire / flag name (`off`, `empty`, `all`, `category`).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "off" => Some(Retrieval::Off),
            "empty" => Some(Retrieval::Empty),
            "all" => Some(Retrieval::All),
            "category" => Some(Retrieval::Category),
            _ => None,
        }
    }
}

/// How many motions a projected joint keeps (see [`ProjectOptions::dominant_motion`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum JointMotion {
    /// NAP: every joint a screw with its rotation and translation ranges.
    #[default]
    Screw,
    /// Only the wider range, compared in units of the range channels' feature scales
    /// ([`range_units`]): each joint rotates, slides or is fixed.
    Dominant,
}

impl JointMotion {
    /// Wire / flag name.
    pub fn as_str(self) -> &'static str {
        match self {
            JointMotion::Screw => "screw",
            JointMotion::Dominant => "dominant",
        }
    }

    /// Parse a wire / flag name (`screw`, `dominant`).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "screw" => Some(JointMotion::Screw),
            "dominant" => Some(JointMotion::Dominant),
            _ => None,
        }
    }
}

/// Whether the projection is repaired and unsupported parts removed (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RepairMode {
    /// The raw projection (NAP).
    #[default]
    Off,
    /// `graph::repair` after projection, `prune` after meshing.
    On,
}

impl RepairMode {
    /// Wire / flag name.
    pub fn as_str(self) -> &'static str {
        match self {
            RepairMode::Off => "off",
            RepairMode::On => "on",
        }
    }

    /// Parse a wire / flag name (`on`, `off`).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "on" => Some(RepairMode::On),
            "off" => Some(RepairMode::Off),
            _ => None,
        }
    }
}

/// The shape side of generation: the decoder that meshes latent parts, the SDF the guidance
/// losses query, and the retrieval codebook.
#[derive(Clone, Copy)]
pub struct PartShapes<'a> {
    /// Decodes latent codes for meshing.
    pub decoder: &'a dyn LatentDecoder,
    /// The part SDF of the guidance losses (the trained shape decoder, e.g. the same
    /// `LatentSdfDecoder` as `decoder`); required when the request has active guidance.
    pub field: Option<&'a dyn SdfField>,
    /// Training codes for [`Retrieval`]; required unless it is `Off`.
    pub codebook: Option<&'a Codebook>,
}

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
    /// Which part shapes are replaced by their nearest codebook code.
    pub retrieval: Retrieval,
    /// Classifier-free category guidance weight; see [`SampleRequest::category_guidance`].
    pub category_guidance: f64,
    /// Steps where the category guidance applies; see [`SampleRequest::category_guidance_below`].
    pub category_guidance_below: Option<usize>,
    /// How many motions each joint keeps.
    pub joint_motion: JointMotion,
    /// Joint repair and part removal.
    pub repair: RepairMode,
    /// Scale hypothesis (module docs): the scan and its cameras are multiplied by this before
    /// sampling, the object divided by it after projection. None (or 1): the scan as given.
    pub scale: Option<f64>,
    /// The scan's frame (module docs; None or the identity: the scan is canonical). The
    /// guidance's points and cameras are moved into the canonical frame before anything else;
    /// objects and meshes stay canonical and [`Generated::frame`] carries it to the exporters.
    pub frame: Option<ScanFrame>,
}

/// Smallest and largest accepted [`GenerateRequest::scale`].
pub const SCALE_RANGE: [f64; 2] = [1.0 / 16.0, 16.0];

/// Most an automatic scale hypothesis changes a scan's size (either way).
pub const AUTO_SCALE_LIMIT: f64 = 4.0;

/// The automatic scale hypothesis: the scale that gives the scan's box diagonal (≈ 0.99 of the
/// object's on the real-asset benchmark's views) the prior's `typical` diagonal for the
/// category, within ×/÷ [`AUTO_SCALE_LIMIT`]; None without points or a typical size.
pub fn auto_scale(points: &[[f32; 3]], typical: Option<f64>) -> Option<f64> {
    let d = super::free_space::extent(points) as f64;
    let t = typical.filter(|t| t.is_finite() && *t > 0.0)?;
    (d.is_finite() && d > 1e-6).then(|| (t / d).clamp(1.0 / AUTO_SCALE_LIMIT, AUTO_SCALE_LIMIT))
}

/// `req.guidance` in the canonical frame (module docs): its points and cameras moved by
/// `req.frame`. What the samples are ranked against, since they come out canonical.
pub fn canonical_guidance(req: &GenerateRequest) -> Option<GuidanceOptions> {
    match (&req.guidance, req.frame.filter(|f| !f.is_canonical())) {
        (Some(g), Some(f)) => Some(GuidanceOptions {
            points: f.points_to_canonical(&g.points),
            cameras: f.points_to_canonical(&g.cameras),
            ..g.clone()
        }),
        (g, _) => g.clone(),
    }
}

/// One generated sample.
#[derive(Debug, Clone)]
pub struct Generated {
    /// Sample index within the request.
    pub index: usize,
    /// Seed it was drawn with.
    pub seed: u64,
    /// The raw (unscaled) graph the model produced, in the sampling frame (the scan times
    /// [`Generated::scale`]).
    pub raw: GraphTensor,
    /// The scale hypothesis the sample was drawn under (1: none); `object` and `meshes` are
    /// back in the scan's frame.
    pub scale: f64,
    /// The scan's frame the sample was drawn for (the identity: canonical input); `object` and
    /// `meshes` are in the canonical frame, `frame.to_scan()` puts them on the scan.
    pub frame: ScanFrame,
    /// The projected object (latent part shapes).
    pub object: ArticulatedObject,
    /// Part meshes, object frame at rest.
    pub meshes: Vec<TriMesh>,
    /// Parts whose code was replaced by the nearest codebook code, ascending (indices before
    /// [`Generated::removed`]).
    pub retrieved: Vec<usize>,
    /// What [`RepairMode::On`] changed in the joints, in order.
    pub repairs: Vec<Repair>,
    /// The parts [`RepairMode::On`] removed, in order.
    pub removed: Vec<Removed>,
}

/// Progress of a generation request.
#[derive(Debug, Clone, PartialEq)]
pub struct GenerateEvent {
    /// Sample being drawn.
    pub sample: usize,
    /// Its diffusion step.
    pub step: StepEvent,
}

/// Generate `req.samples` objects without guidance (a request with active guidance is refused
/// with an error naming `guidance` — use [`generate_with`] with a field).
pub fn generate(
    denoiser: &Denoiser,
    decoder: &dyn LatentDecoder,
    codebook: Option<&Codebook>,
    scales: &FeatureScales,
    schedule: &Schedule,
    req: &GenerateRequest,
    on_step: &mut dyn FnMut(&GenerateEvent) -> ControlFlow<String>,
) -> Result<Vec<Generated>, EngineError> {
    let shapes = PartShapes {
        decoder,
        field: None,
        codebook,
    };
    generate_with(denoiser, &shapes, scales, schedule, req, on_step)
}

/// Generate `req.samples` objects; `shapes.field` is required when `req.guidance` has a
/// positive weight, `shapes.codebook` when `req.retrieval` is not `Off`.
pub fn generate_with(
    denoiser: &Denoiser,
    shapes: &PartShapes,
    scales: &FeatureScales,
    schedule: &Schedule,
    req: &GenerateRequest,
    on_step: &mut dyn FnMut(&GenerateEvent) -> ControlFlow<String>,
) -> Result<Vec<Generated>, EngineError> {
    if req.retrieval != Retrieval::Off && shapes.codebook.is_none() {
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: "retrieval".into(),
            limit:
                "\"off\" for weights without a codebook (manifest.json has no \"codebook\" entry)"
                    .into(),
            value: format!("{:?}", req.retrieval.as_str()),
        }));
    }
    // Category retrieval: a category, codes with categories, and some of that category.
    let snap_category = match (req.retrieval, shapes.codebook) {
        (Retrieval::Category, Some(codebook)) => {
            let invalid = |limit: &str, value: String| {
                EngineError::Invalid(crate::error::Invalid {
                    field: "retrieval".into(),
                    limit: limit.into(),
                    value,
                })
            };
            let Some(c) = req.category else {
                return Err(invalid(
                    "a category with \"category\" (it takes the requested category's codes)",
                    "\"category\" without a category".into(),
                ));
            };
            if codebook.categories().is_none() {
                return Err(invalid(
                    "a codebook whose codes carry categories (manifest codebook.config.categories; rebuild it with `physnap train codebook` from a `train encode` directory)",
                    "\"category\"".into(),
                ));
            }
            if codebook.rows_of_category(c) == 0 {
                return Err(EngineError::Invalid(crate::error::Invalid {
                    field: "category".into(),
                    limit:
                        "a category with training codes in the codebook (retrieval \"category\")"
                            .into(),
                    value: req
                        .category_name
                        .clone()
                        .unwrap_or_else(|| format!("index {c}")),
                }));
            }
            Some(c)
        }
        _ => None,
    };
    let scale = match req.scale {
        Some(s) if !(s.is_finite() && (SCALE_RANGE[0]..=SCALE_RANGE[1]).contains(&s)) => {
            return Err(EngineError::Invalid(crate::error::Invalid {
                field: "scale".into(),
                limit: format!("finite, in [{}, {}]", SCALE_RANGE[0], SCALE_RANGE[1]),
                value: s.to_string(),
            }));
        }
        Some(s) if s != 1.0 => Some(s),
        _ => None,
    };
    // The guidance in the canonical frame, then in the sampling frame.
    let frame = req.frame.filter(|f| !f.is_canonical());
    let canonical = canonical_guidance(req);
    let guidance = match (&canonical, scale) {
        (Some(g), Some(s)) => {
            let mul = |v: &[[f32; 3]]| -> Vec<[f32; 3]> {
                v.iter().map(|p| p.map(|x| (x as f64 * s) as f32)).collect()
            };
            Some(GuidanceOptions {
                points: mul(&g.points),
                cameras: mul(&g.cameras),
                ..g.clone()
            })
        }
        (g, _) => g.clone(),
    };
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
                guidance: guidance.clone(),
                sampler: req.sampler,
                steps: req.steps,
                category_guidance: req.category_guidance,
                category_guidance_below: req.category_guidance_below,
            },
            shapes.field.map(|field| GuidanceContext { field, scales }),
            &device,
            &mut |s| {
                on_step(&GenerateEvent {
                    sample: i,
                    step: s.clone(),
                })
            },
        )?;
        let raw = graphs[0].unscaled(scales);
        let mut object = project(
            &raw,
            &ProjectOptions {
                name: format!("sample_{i:03}"),
                category: req.category_name.clone(),
                dominant_motion: (req.joint_motion == JointMotion::Dominant)
                    .then(|| range_units(scales)),
                ..Default::default()
            },
        )
        .map_err(|e| {
            EngineError::Invalid(crate::error::Invalid {
                field: "sample".into(),
                limit: "a projectable graph".into(),
                value: e.to_string(),
            })
        })?;
        if let Some(s) = scale {
            object = object.scaled(1.0 / s);
        }
        let mut repairs = match req.repair {
            RepairMode::On => repair(&mut object),
            RepairMode::Off => Vec::new(),
        };
        let codebook = shapes.codebook.filter(|_| req.retrieval != Retrieval::Off);
        // All / Category: every latent code is replaced before meshing, so each part is meshed
        // once.
        let mut retrieved = match codebook {
            Some(codebook) if matches!(req.retrieval, Retrieval::All | Retrieval::Category) => {
                let mut replaced = Vec::new();
                for (i, part) in object.parts.iter_mut().enumerate() {
                    if snap_code(i, part, codebook, snap_category)? {
                        replaced.push(i);
                    }
                }
                replaced
            }
            _ => Vec::new(),
        };
        let mut meshes = crate::mesh::mesh_parts(&object, Some(shapes.decoder), &req.meshing)
            .map_err(meshing_err)?;
        if let Some(codebook) = codebook.filter(|_| req.retrieval == Retrieval::Empty) {
            retrieved = retrieve_shapes(
                &mut object,
                &mut meshes,
                shapes.decoder,
                codebook,
                Retrieval::Empty,
                &req.meshing,
            )?;
        }
        let removed = match req.repair {
            RepairMode::On => {
                let free = canonical
                    .as_ref()
                    .filter(|g| !g.cameras.is_empty())
                    .map(|g| FreeSpace::new(&g.points, &g.cameras));
                let (removed, attached) = prune(&mut object, &mut meshes, free.as_ref());
                repairs.extend(attached);
                removed
            }
            RepairMode::Off => Vec::new(),
        };
        out.push(Generated {
            index: i,
            seed,
            raw,
            scale: scale.unwrap_or(1.0),
            frame: frame.unwrap_or_default(),
            object,
            meshes,
            retrieved,
            repairs,
            removed,
        });
    }
    Ok(out)
}

/// The units [rad, m] in which [`JointMotion::Dominant`] compares a joint's two range
/// widths: the larger feature scale of each range's two channels (the model's own sense of a
/// "typical" range; 1 where a scale is missing or degenerate).
pub fn range_units(scales: &FeatureScales) -> [f64; 2] {
    use crate::graph::edge_ch;
    let unit = |c: usize| {
        let s = scales
            .edge
            .get(c..c + 2)
            .map_or(0.0, |s| s[0].abs().max(s[1].abs()) as f64);
        if s.is_finite() && s > 1e-6 { s } else { 1.0 }
    };
    [unit(edge_ch::REVOLUTE), unit(edge_ch::PRISMATIC)]
}

fn meshing_err(e: crate::error::CoreError) -> EngineError {
    EngineError::Invalid(crate::error::Invalid {
        field: "meshing".into(),
        limit: "valid meshing options".into(),
        value: e.to_string(),
    })
}

/// Replace the latent shapes `mode` selects (empty meshes, or all; `Category` acts as `All`
/// here, there is no category to restrict to) by their nearest codebook code and mesh those
/// parts again; returns the replaced part indices. Parts with analytic
/// shapes are left alone. `meshes[i]` must be part i's mesh.
pub fn retrieve_shapes(
    object: &mut ArticulatedObject,
    meshes: &mut [TriMesh],
    decoder: &dyn LatentDecoder,
    codebook: &Codebook,
    mode: Retrieval,
    meshing: &MeshingOptions,
) -> Result<Vec<usize>, EngineError> {
    let mut replaced = Vec::new();
    if mode == Retrieval::Off {
        return Ok(replaced);
    }
    for (i, (part, mesh)) in object.parts.iter_mut().zip(meshes.iter_mut()).enumerate() {
        if mode == Retrieval::Empty && !mesh.triangles.is_empty() {
            continue;
        }
        if snap_code(i, part, codebook, None)? {
            *mesh = part_mesh(part, Some(decoder), meshing).map_err(meshing_err)?;
            replaced.push(i);
        }
    }
    Ok(replaced)
}

/// Replace part `i`'s latent code by its nearest codebook code (among `category`'s codes when
/// given; the caller has checked that there are some); false for analytic shapes.
fn snap_code(
    i: usize,
    part: &mut crate::object::Part,
    codebook: &Codebook,
    category: Option<usize>,
) -> Result<bool, EngineError> {
    let PartShape::Latent(code) = &part.shape else {
        return Ok(false);
    };
    let Some((row, _)) = codebook.nearest_in(code, category) else {
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: format!("part {i} shape code"),
            limit: format!("{} values (the codebook's latent size)", codebook.latent()),
            value: code.len().to_string(),
        }));
    };
    part.shape = PartShape::Latent(codebook.row(row).to_vec());
    Ok(true)
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::object::Part;
    use crate::shape::SphereCodes as Spheres;

    fn part(name: &str, shape: PartShape) -> Part {
        Part {
            name: name.into(),
            half_extents: Vector3::repeat(0.1),
            center: Vector3::zeros(),
            shape,
        }
    }

    fn object() -> ArticulatedObject {
        let mut o = crate::fixtures::cabinet();
        let n = o.parts.len();
        assert!(
            n >= 3,
            "the fixture has a body and at least two moving parts"
        );
        o.parts[0] = part("base", PartShape::Latent(vec![-0.3, 0.0]));
        o.parts[1] = part("door", PartShape::Latent(vec![0.2, 1.0]));
        o.parts[2] = part("box", PartShape::Box);
        o
    }

    #[test]
    fn retrieval_replaces_empty_latent_shapes_with_the_nearest_code() {
        let meshing = MeshingOptions { resolution: 16 };
        // Row 1 is nearest to the empty base's code [-0.3, 0]; every row is non-empty.
        let codebook = Codebook::new(2, vec![0.4, 3.0, 0.25, 0.1, 0.3, 1.1]).unwrap();
        // Mesh `obj`, run retrieval in `mode`: (object, meshes, replaced parts) or the error.
        let run = |mut obj: ArticulatedObject, mode| {
            let mut meshes = crate::mesh::mesh_parts(&obj, Some(&Spheres), &meshing).unwrap();
            retrieve_shapes(&mut obj, &mut meshes, &Spheres, &codebook, mode, &meshing)
                .map(|got| (obj, meshes, got))
        };
        let before = crate::mesh::mesh_parts(&object(), Some(&Spheres), &meshing).unwrap();
        assert!(before[0].triangles.is_empty() && !before[1].triangles.is_empty());
        let (obj, meshes, got) = run(object(), Retrieval::Empty).unwrap();
        assert_eq!(got, vec![0]);
        assert_eq!(obj.parts[0].shape, PartShape::Latent(vec![0.25, 0.1]));
        assert!(
            !meshes[0].triangles.is_empty(),
            "the base now has a surface"
        );
        assert_eq!(obj.parts[1].shape, PartShape::Latent(vec![0.2, 1.0]));
        assert_eq!(meshes[1], before[1], "non-empty shapes are untouched");

        // All: every latent part takes its nearest code; analytic parts are left alone.
        let (obj, _, got) = run(object(), Retrieval::All).unwrap();
        assert_eq!(got, vec![0, 1]);
        assert_eq!(obj.parts[1].shape, PartShape::Latent(vec![0.3, 1.1]));
        assert_eq!(obj.parts[2].shape, PartShape::Box);
        // Off changes nothing.
        let (obj, meshes, got) = run(object(), Retrieval::Off).unwrap();
        assert!(got.is_empty());
        assert_eq!((obj, meshes), (object(), before));
        // A code of the wrong length is refused, naming the part and the size.
        let mut obj = object();
        obj.parts[0].shape = PartShape::Latent(vec![-1.0]);
        let e = run(obj, Retrieval::Empty).unwrap_err().to_string();
        assert!(
            e.contains("part 0 shape code") && e.contains("2 values"),
            "{e}"
        );
    }

    /// A one-layer denoiser with `categories` categories (untrained: seeded init).
    fn tiny_denoiser(categories: usize) -> Denoiser {
        use crate::model::denoiser::DenoiserConfig;
        Denoiser::new(
            &DenoiserConfig {
                width: 16,
                layers: 1,
                head_channels: 8,
                node_head_hidden: vec![16],
                edge_head_hidden: vec![16],
                categories,
                ..DenoiserConfig::default()
            },
            &crate::model::cpu(),
        )
        .unwrap()
    }

    #[test]
    fn category_retrieval_takes_every_code_from_the_requested_category() {
        let denoiser = tiny_denoiser(3);
        // Sphere codes (radius = first entry): row 0 is category 1, rows 1 and 2 category 2.
        let row = |r: f32| {
            let mut c = vec![0.0f32; 128];
            c[0] = r;
            c
        };
        let codes: Vec<f32> = [row(0.3), row(0.2), row(0.25)].concat();
        let plain = Codebook::new(128, codes).unwrap();
        let codebook = plain.clone().with_categories(vec![1, 2, 2], 3).unwrap();
        let req = |category: Option<usize>| GenerateRequest {
            samples: 2,
            steps: 5,
            category,
            category_name: category.map(|c| format!("cat{c}")),
            retrieval: Retrieval::Category,
            ..Default::default()
        };
        let run = |cb: &Codebook, r: &GenerateRequest| {
            let mut steps = 0;
            let got = generate(
                &denoiser,
                &Spheres,
                Some(cb),
                &FeatureScales::default(),
                &Schedule::default(),
                r,
                &mut |_| {
                    steps += 1;
                    ControlFlow::Continue(())
                },
            );
            (got, steps)
        };
        // The same seeds without retrieval give the model's own codes.
        let (raw, _) = run(
            &codebook,
            &GenerateRequest {
                retrieval: Retrieval::Off,
                ..req(Some(2))
            },
        );
        let (got, _) = run(&codebook, &req(Some(2)));
        for (g, raw) in got.unwrap().iter().zip(raw.unwrap()) {
            let latent: Vec<usize> = (0..raw.object.parts.len())
                .filter(|&i| matches!(raw.object.parts[i].shape, PartShape::Latent(_)))
                .collect();
            assert!(!latent.is_empty());
            assert_eq!(g.retrieved, latent, "every latent part is replaced");
            for &i in &latent {
                let (PartShape::Latent(code), PartShape::Latent(own)) =
                    (&g.object.parts[i].shape, &raw.object.parts[i].shape)
                else {
                    unreachable!("part {i} is latent in both runs")
                };
                let (want, _) = codebook.nearest_in(own, Some(2)).unwrap();
                assert_eq!(code, codebook.row(want), "part {i}");
                assert_ne!(code, codebook.row(0), "never a code of category 1");
            }
        }
        // Refused before sampling: no category, codes without categories, a category without
        // codes.
        let (e, steps) = run(&codebook, &req(None));
        let e = e.unwrap_err().to_string();
        assert!(
            e.contains("retrieval") && e.contains("without a category"),
            "{e}"
        );
        assert_eq!(steps, 0);
        let (e, steps) = run(&plain, &req(Some(2)));
        let e = e.unwrap_err().to_string();
        assert!(e.contains("carry categories"), "{e}");
        assert_eq!(steps, 0);
        let (e, steps) = run(&codebook, &req(Some(0)));
        let e = e.unwrap_err().to_string();
        assert!(e.contains("category") && e.contains("cat0"), "{e}");
        assert_eq!(steps, 0);
        assert_eq!(Retrieval::Category.without_category(), Retrieval::Empty);
        assert_eq!(Retrieval::All.without_category(), Retrieval::All);
    }

    #[test]
    fn retrieval_without_a_codebook_is_refused_before_sampling() {
        let denoiser = tiny_denoiser(crate::data::categories::CATEGORIES.len());
        let mut steps = 0;
        let e = generate(
            &denoiser,
            &Spheres,
            None,
            &FeatureScales::default(),
            &Schedule::default(),
            &GenerateRequest {
                samples: 1,
                retrieval: Retrieval::Empty,
                ..Default::default()
            },
            &mut |_| {
                steps += 1;
                ControlFlow::Continue(())
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("retrieval") && e.contains("\"empty\"") && e.contains("codebook"),
            "{e}"
        );
        assert_eq!(steps, 0);
        for r in [
            Retrieval::Off,
            Retrieval::Empty,
            Retrieval::All,
            Retrieval::Category,
        ] {
            assert_eq!(Retrieval::parse(r.as_str()), Some(r));
        }
        assert_eq!(Retrieval::parse("auto"), None);
        for m in [JointMotion::Screw, JointMotion::Dominant] {
            assert_eq!(JointMotion::parse(m.as_str()), Some(m));
        }
        assert_eq!(JointMotion::parse("revolute"), None);
    }
}
