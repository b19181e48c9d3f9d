//! PhysNAP's guidance metrics of one sample (method.md §8.8, §9 A9).
//!
//! ```text
//! S     = slots of the extracted object (top-2 forced, õ > 0.5; graph::project)
//! E_pc  = (1/M) Σ_j min_{i ∈ S} d(p_j, i)²                 (part SDF of §8.3, no soft assignment)
//! D_pc  = (1/M) Σ_j dist(p_j, ∪ part meshes)               (meshes placed by the fixed mapping)
//! E_pen = ℓ_pen over S without existence weights           (V_el incl. 10⁵, ordered pairs)
//! E_mob = mean over 5 states k/4 (synchronised γ, d) of the ℓ_mob sweep over the object's tree
//!         joints (MST of §5.4, class by argmax), without edge weights, factor 2 kept
//! O_mesh = mean over the same 5 states of  Σ_i A_i · #{p ∈ X_i : ∃ j ≠ i, p inside M_j deeper
//!          than δ} / |X_i|  /  Σ_i A_i          (X_i: area-weighted samples of part mesh M_i,
//!          A_i its area, δ = 5 mm; physnap's addition, see below)
//! ```
//!
//! E_pen and E_mob integrate the decoder's own field, so they are in its units: a decoder whose
//! field is twice as steep reports about four times the overlap for the same meshes. O_mesh
//! measures the same failure on the extracted meshes — the share of the parts' surface buried
//! inside another part, at rest and while the joints move — so it compares across decoders.
//!
//! [`guided_table`] runs the paper's Table 1 (category-aware no/yes × pc+pen+mob, pc+pen, pc+mob,
//! pc, uncond; medians over all samples; diverged samples counted, not measured). MMD and 1-NNA
//! are "per point cloud" (paper §4, method.md §8.8): for every cloud, its generated samples
//! against that cloud's reference objects ([`TableOptions::references`]), with the instantiation
//! distance of §7.1 and the PointFlow set order; the row reports the median over the clouds.
//! Beyond the paper, each row also carries the mean E_pen / E_mob and the share of samples in
//! which they are non-zero: with a prior whose samples rarely overlap, every median is 0.
//!
//! Choices (§9 A9): the tree joints and the mean over states as recommended; the factor 2 of
//! ℓ_mob is kept so E_mob and E_pen count pairs alike. All SDF queries go through the same
//! batched tensor code as the losses ([`crate::engine::guidance`]), on the plain device.

use std::ops::ControlFlow;

use burn::tensor::{Tensor, TensorData};

use crate::engine::EngineError;
use crate::engine::generate::{GenerateRequest, JointMotion, PartShapes, Retrieval, generate_with};
use crate::engine::guidance::{GuidanceOptions, Terms, weights_active};
use crate::engine::sample::{Sampler, category_guidance, category_guidance_below};
use crate::engine::schedule::Schedule;
use crate::graph::FeatureScales;
use crate::mesh::MeshingOptions;
use crate::model::codebook::Codebook;
use crate::model::denoiser::Denoiser;
use crate::model::shape_prior::LatentSdfDecoder;

use crate::data::rng::Rng;
use crate::engine::guidance::field::part_sdf;
use crate::engine::guidance::grid::ints;
use crate::engine::guidance::{SdfField, decode, mob, pen};
use crate::eval::generative::{
    DistributionMetrics, IdOptions, MetricOrder, StateClouds, distance_matrix,
    distribution_metrics, instantiation_distance, state_clouds,
};
use crate::graph::project::{existing_slots, spanning_tree};
use crate::graph::{EDGE_DIM, GraphTensor, K, NODE_DIM, NUM_EDGES, edge_ch, edge_index};
use crate::mesh::TriMesh;
use crate::mesh::bvh::MeshBvh;
use crate::object::ArticulatedObject;
use nalgebra::Point3;

/// Existence threshold of the metrics.
pub const EXIST_THRESHOLD: f32 = 0.5;

/// The four guidance metrics of one sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GuidedMetrics {
    /// E_pc.
    pub e_pc: f64,
    /// D_pc (NaN when the sample has no mesh triangles).
    pub d_pc: f64,
    /// E_pen.
    pub e_pen: f64,
    /// E_mob.
    pub e_mob: f64,
    /// O_mesh (NaN when no part mesh has area).
    pub o_mesh: f64,
}

/// Depth δ (metres) beyond which a surface sample inside another part's mesh counts in O_mesh:
/// parts that merely touch (a door closed against its frame) stay below it despite meshing
/// error.
pub const MESH_OVERLAP_DEPTH: f32 = 0.005;

/// Area-weighted surface samples per part mesh in O_mesh.
pub const MESH_OVERLAP_SAMPLES: usize = 256;

/// E_pc, E_pen and E_mob of a raw (unscaled) graph; D_pc needs meshes ([`d_pc`]).
pub fn sdf_metrics(field: &dyn SdfField, raw: &GraphTensor, points: &[[f32; 3]]) -> GuidedMetrics {
    let device = crate::model::cpu();
    let slots = existing_slots(raw, EXIST_THRESHOLD);
    let nodes = Tensor::<2>::from_data(TensorData::new(raw.nodes.clone(), [K, NODE_DIM]), &device);
    let edges = Tensor::<2>::from_data(
        TensorData::new(raw.edges.clone(), [NUM_EDGES, EDGE_DIM]),
        &device,
    );
    let mut d = decode(nodes, edges, field.latent());
    let mask: Vec<f32> = (0..K)
        .map(|s| if slots.contains(&s) { 1.0 } else { 0.0 })
        .collect();
    d.host.exist = mask.clone();
    let indicator = Tensor::<1>::from_data(TensorData::new(mask, [K]), &device);
    let scalar = |t: Option<Tensor<1>>| t.map_or(0.0, |t| t.into_scalar::<f32>() as f64);

    let e_pc = if points.is_empty() || slots.is_empty() {
        f64::NAN
    } else {
        let m = points.len();
        let flat: Vec<f32> = points.iter().flatten().copied().collect();
        let p = Tensor::<2>::from_data(TensorData::new(flat, [m, 3]), &device);
        let idx: Vec<i64> = slots
            .iter()
            .flat_map(|&s| std::iter::repeat_n(s as i64, m))
            .collect();
        let idx = ints(idx, &device);
        let u = p.repeat_dim(0, slots.len()) - d.parts.centres.clone().select(0, idx.clone());
        let d2 = part_sdf(field, &d.parts, idx, u)
            .reshape([slots.len(), m])
            .powi_scalar(2);
        d2.min_dim(0).mean().into_scalar::<f32>() as f64
    };
    let e_pen = scalar(pen::loss(field, &d.parts, indicator, &d.host));
    let joints: Vec<(usize, usize)> = spanning_tree(raw, &slots)
        .into_iter()
        .map(|(i, j)| {
            let idx = edge_index(i, j);
            let c = &raw.edge(idx)[edge_ch::CLASS..edge_ch::DIR];
            (idx, if c[1] >= c[2] { 1 } else { 2 })
        })
        .collect();
    let items = mob::metric_items(&joints);
    let weights = Tensor::<1>::from_data(
        TensorData::new(
            vec![mob::PAIR_FACTOR / mob::METRIC_STATES as f32; items.len()],
            [items.len()],
        ),
        &device,
    );
    let e_mob = scalar(mob::sweep(field, &d.parts, d.edges, &items, weights));
    GuidedMetrics {
        e_pc,
        d_pc: f64::NAN,
        e_pen,
        e_mob,
        o_mesh: f64::NAN,
    }
}

/// O_mesh of `obj` with one mesh per part (object frame at rest): the share of the parts'
/// surface area lying more than [`MESH_OVERLAP_DEPTH`] inside another part's mesh, mean over
/// the joint states k/4, k = 0..4, every joint at the same fraction of its range. Sampling is
/// seeded; NaN when the meshes do not match the parts or none has area.
pub fn mesh_overlap(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    samples_per_part: usize,
    seed: u64,
) -> f64 {
    if meshes.len() != obj.parts.len() || samples_per_part == 0 {
        return f64::NAN;
    }
    let bvhs: Vec<Option<MeshBvh>> = meshes
        .iter()
        .map(|m| {
            if m.triangles.is_empty() {
                None
            } else {
                MeshBvh::new(&m.positions, &m.triangles).ok()
            }
        })
        .collect();
    let bounds: Vec<Option<([f32; 3], [f32; 3])>> = meshes.iter().map(TriMesh::bounds).collect();
    let mut rng = Rng::new(seed);
    let mut uniform = || rng.uniform();
    let samples: Vec<Vec<[f32; 3]>> = bvhs
        .iter()
        .map(|b| {
            b.as_ref().map_or_else(Vec::new, |b| {
                b.sample_surface(samples_per_part, &mut uniform)
                    .into_iter()
                    .map(|(p, _)| p)
                    .collect()
            })
        })
        .collect();
    let areas: Vec<f64> = bvhs
        .iter()
        .map(|b| b.as_ref().map_or(0.0, MeshBvh::total_area))
        .collect();
    let total: f64 = areas.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return f64::NAN;
    }
    let depth = MESH_OVERLAP_DEPTH;
    let inside_bounds = |p: &Point3<f64>, b: &([f32; 3], [f32; 3])| {
        (0..3).all(|k| p[k] > (b.0[k] + depth) as f64 && p[k] < (b.1[k] - depth) as f64)
    };
    let mut share = 0.0;
    for k in 0..OVERLAP_STATES {
        let f = k as f64 / (OVERLAP_STATES - 1) as f64;
        let motions = obj.part_motions(&obj.states_at(f));
        let inverse: Vec<_> = motions.iter().map(|m| m.inverse()).collect();
        let mut buried = 0.0;
        for (i, pts) in samples.iter().enumerate() {
            let hits = pts
                .iter()
                .filter(|p| {
                    let world = motions[i] * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    (0..meshes.len()).any(|j| {
                        let (Some(bvh), Some(b)) = (&bvhs[j], &bounds[j]) else {
                            return false;
                        };
                        let q = inverse[j] * world;
                        if j == i || !inside_bounds(&q, b) {
                            return false;
                        }
                        let q = [q.x as f32, q.y as f32, q.z as f32];
                        bvh.is_inside(q)
                            && bvh
                                .closest_point(q)
                                .is_some_and(|(_, d2, _)| d2 > depth * depth)
                    })
                })
                .count();
            buried += areas[i] * hits as f64 / pts.len().max(1) as f64;
        }
        share += buried / total;
    }
    share / OVERLAP_STATES as f64
}

/// Joint states of O_mesh (k/4, k = 0..4, as E_mob's metric states).
const OVERLAP_STATES: usize = 5;

/// D_pc: mean distance from `points` to the union of `meshes` (object frame at rest); NaN when
/// there are no triangles or no points.
pub fn d_pc(meshes: &[TriMesh], points: &[[f32; 3]]) -> f64 {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for m in meshes {
        let base = positions.len() as u32;
        positions.extend_from_slice(&m.positions);
        triangles.extend(m.triangles.iter().map(|t| t.map(|v| v + base)));
    }
    if triangles.is_empty() || points.is_empty() {
        return f64::NAN;
    }
    let Ok(bvh) = MeshBvh::new(&positions, &triangles) else {
        return f64::NAN;
    };
    let sum: f64 = points
        .iter()
        .map(|p| {
            bvh.closest_point(*p)
                .map_or(f64::NAN, |(_, d2, _)| (d2 as f64).sqrt())
        })
        .sum();
    sum / points.len() as f64
}

/// Every metric of a generated sample (`obj` and `meshes` as generation returns them; O_mesh
/// sampled with `seed`). `raw` was drawn under the scale hypothesis `scale` (1: none), so
/// E_pc, E_pen and E_mob are measured in that frame (the points times `scale`); D_pc and
/// O_mesh in the scan's.
pub fn metrics(
    field: &dyn SdfField,
    raw: &GraphTensor,
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    points: &[[f32; 3]],
    scale: f64,
    seed: u64,
) -> GuidedMetrics {
    let sdf = if scale == 1.0 {
        sdf_metrics(field, raw, points)
    } else {
        let scaled: Vec<[f32; 3]> = points
            .iter()
            .map(|p| p.map(|x| (x as f64 * scale) as f32))
            .collect();
        sdf_metrics(field, raw, &scaled)
    };
    GuidedMetrics {
        d_pc: d_pc(meshes, points),
        o_mesh: mesh_overlap(obj, meshes, MESH_OVERLAP_SAMPLES, seed),
        ..sdf
    }
}

/// Median of the finite values (NaN when there are none), as the paper reports per variant.
pub fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// A guidance variant of the paper's Table 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Variant {
    /// Row label.
    pub name: &'static str,
    /// Active terms (None: unguided).
    pub terms: Option<Terms>,
}

/// Table 1's five variants, in the paper's order.
pub const VARIANTS: [Variant; 5] = [
    Variant {
        name: "pc+pen+mob",
        terms: Some(Terms::ALL),
    },
    Variant {
        name: "pc+pen",
        terms: Some(Terms {
            pc: true,
            pen: true,
            mob: false,
        }),
    },
    Variant {
        name: "pc+mob",
        terms: Some(Terms {
            pc: true,
            pen: false,
            mob: true,
        }),
    },
    Variant {
        name: "pc",
        terms: Some(Terms {
            pc: true,
            pen: false,
            mob: false,
        }),
    },
    Variant {
        name: "uncond",
        terms: None,
    },
];

/// An observed test cloud.
#[derive(Debug, Clone, PartialEq)]
pub struct Cloud {
    /// Identifier (object id).
    pub id: String,
    /// Category index of the scanned object, if known (category-aware rows need it).
    pub category: Option<usize>,
    /// Points, object frame.
    pub points: Vec<[f32; 3]>,
}

/// Settings of a Table 1 run.
#[derive(Debug, Clone, PartialEq)]
pub struct TableOptions {
    /// Samples per cloud and variant (paper: 15).
    pub samples_per_cloud: usize,
    /// Seed of sample k of cloud c: seed + (first_cloud + c) · samples_per_cloud + k (same
    /// across variants).
    pub seed: u64,
    /// Index of the first cloud in the whole test set, when the run covers a slice of it
    /// (`eval guided --skip-clouds`): the slice's samples get the seeds a full run gives them.
    pub first_cloud: usize,
    /// Category-aware blocks to run (false: unconditional model input; true: the cloud's category).
    pub category_aware: Vec<bool>,
    /// Names of the [`VARIANTS`] to run, in the table's order (empty: all five).
    pub variants: Vec<String>,
    /// Guided steps n_g.
    pub guided_steps: usize,
    /// τ.
    pub tau: f64,
    /// Multipliers of the paper's weights of ℓ_pc, ℓ_pen and ℓ_mob in every guided row
    /// ([1, 1, 1]: the paper's table). Lets one table measure, say, a doubled ℓ_pen against the
    /// same scans and seeds.
    pub loss_scales: [f64; 3],
    /// Optional clamp of the guidance gradient (a deviation; see `GuidanceOptions::max_step`).
    pub max_step: Option<f64>,
    /// Refinement steps after sampling (see `GuidanceOptions::refine_steps`).
    pub refine_steps: usize,
    /// Physics-only refinement steps after those (see `GuidanceOptions::refine_physics_steps`).
    pub refine_physics_steps: usize,
    /// Reverse-step rule and count.
    pub sampler: Sampler,
    /// Reverse steps (0: all).
    pub steps: usize,
    /// Meshing for D_pc.
    pub meshing: MeshingOptions,
    /// Per cloud (same order as the clouds), the reference objects of its MMD / 1-NNA, already
    /// prepared for the instantiation distance with [`Self::id`]. Empty (or shorter than the
    /// clouds): no generative metrics for those clouds.
    pub references: Vec<Vec<StateClouds>>,
    /// Per cloud, whether `references[c][0]` is the scanned object itself. For those clouds each
    /// sample's instantiation distance to it (ID_gt, the completion's distance to the object
    /// the scan came from, unobserved side included) is recorded.
    pub scanned: Vec<bool>,
    /// States and points of the instantiation distance.
    pub id: IdOptions,
    /// Which part shapes are replaced by their nearest codebook code (needs a codebook).
    pub retrieval: Retrieval,
    /// Classifier-free category guidance of the category-aware rows; None: each row's default
    /// ([`category_guidance`] of whether the row is guided).
    pub category_guidance: Option<f64>,
    /// Steps where it applies, see [`GenerateRequest::category_guidance_below`]; None: each
    /// row's default ([`category_guidance_below`] of whether the row is guided).
    pub category_guidance_below: Option<usize>,
    /// How many motions each joint keeps; see [`GenerateRequest::joint_motion`].
    pub joint_motion: JointMotion,
}

/// One row of Table 1: medians over all samples of all clouds.
#[derive(Debug, Clone, PartialEq)]
pub struct TableRow {
    /// Category-aware block.
    pub category_aware: bool,
    /// Variant name (Table 1) or sweep point label.
    pub variant: String,
    /// The guidance this row ran (None: unguided).
    pub guidance: Option<GuidanceSetting>,
    /// The category guidance weight and its time limit this row ran, resolved from
    /// [`TableOptions`] (None: a category-unaware row).
    pub category_guidance: Option<(f64, usize)>,
    /// Median E_pc.
    pub e_pc: f64,
    /// Median D_pc.
    pub d_pc: f64,
    /// Median E_pen.
    pub e_pen: f64,
    /// Median E_mob.
    pub e_mob: f64,
    /// Mean E_pen. Medians hide rare overlaps: when most samples do not overlap at all, the
    /// median is 0 in every row, and only the mean and the share below can show what the
    /// penetration term changes.
    pub e_pen_mean: f64,
    /// Mean E_mob.
    pub e_mob_mean: f64,
    /// Share of samples with E_pen > 0 (parts overlapping at rest).
    pub pen_share: f64,
    /// Share of samples with E_mob > 0 (parts colliding when moved).
    pub mob_share: f64,
    /// Mean O_mesh (share of the parts' surface buried in another part, on the meshes).
    pub o_mesh_mean: f64,
    /// Share of samples with O_mesh > 0.
    pub o_mesh_share: f64,
    /// Median over clouds of the per-cloud MMD (NaN without references).
    pub mmd: f64,
    /// Median over clouds of the per-cloud 1-NNA (NaN without references).
    pub one_nna: f64,
    /// Median over samples of ID_gt, the instantiation distance to the scanned object (NaN
    /// when no cloud's object is known).
    pub id_gt: f64,
    /// Mean ID_gt.
    pub id_gt_mean: f64,
    /// Samples that finished.
    pub samples: usize,
    /// Samples that diverged (reported, excluded from the medians).
    pub diverged: usize,
    /// Mean wall time per sample (s), sampling + meshing + metrics.
    pub seconds_per_sample: f64,
    /// Every sample of the row, in run order (the medians hide which scan and seed overlap).
    pub per_sample: Vec<SampleRecord>,
}

/// One sample of a [`TableRow`].
#[derive(Debug, Clone, PartialEq)]
pub struct SampleRecord {
    /// Cloud id.
    pub cloud: String,
    /// The sample's seed.
    pub seed: u64,
    /// (E_pc, D_pc, E_pen, E_mob, O_mesh); None when the sample diverged.
    pub metrics: Option<[f64; 5]>,
    /// Instantiation distance to the scanned object; None when it is not known (no `--data`,
    /// the object is not in it) or the sample diverged or has no surface.
    pub id_gt: Option<f64>,
    /// Wall time of this sample (s), sampling + meshing + metrics.
    pub seconds: f64,
}

/// Run the guidance table: every block × variant × cloud × sample. `on_sample` gets
/// (done, total) after each sample.
#[allow(clippy::too_many_arguments)]
pub fn guided_table(
    denoiser: &Denoiser,
    decoder: &LatentSdfDecoder,
    codebook: Option<&Codebook>,
    scales: &FeatureScales,
    schedule: &Schedule,
    clouds: &[Cloud],
    opts: &TableOptions,
    on_sample: &mut dyn FnMut(usize, usize),
) -> Result<Vec<TableRow>, EngineError> {
    let specs = table_rows(opts)?;
    run_rows(
        denoiser, decoder, codebook, scales, schedule, clouds, opts, &specs, on_sample,
    )
}

/// The rows of Table 1 that `opts` selects: its category blocks × its variants (all five when
/// `opts.variants` is empty) with the paper's guidance settings. Unknown variant names are
/// refused, naming the allowed ones.
pub fn table_rows(opts: &TableOptions) -> Result<Vec<RowSpec>, EngineError> {
    let variants: Vec<Variant> = VARIANTS
        .into_iter()
        .filter(|v| opts.variants.is_empty() || opts.variants.iter().any(|n| n == v.name))
        .collect();
    if let Some(unknown) = opts
        .variants
        .iter()
        .find(|n| !VARIANTS.iter().any(|v| &v.name == n))
    {
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: "variants".into(),
            limit: format!("names among {}", VARIANTS.map(|v| v.name).join(", ")),
            value: unknown.clone(),
        }));
    }
    if let Some((name, v)) = ["pc", "pen", "mob"]
        .into_iter()
        .zip(opts.loss_scales)
        .find(|(_, v)| !(v.is_finite() && (0.0..=100.0).contains(v)))
    {
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: format!("loss_scales.{name}"),
            limit: "finite, in [0, 100]".into(),
            value: v.to_string(),
        }));
    }
    let specs: Vec<RowSpec> = opts
        .category_aware
        .iter()
        .flat_map(|&aware| {
            variants.iter().map(move |v| RowSpec {
                category_aware: aware,
                label: v.name.to_string(),
                guidance: v.terms.map(|t| {
                    GuidanceSetting::scaled(t, opts.loss_scales, opts.guided_steps, opts.tau)
                }),
            })
        })
        .collect();
    Ok(specs)
}

/// Guidance of one row: weights, n_g (diffusion time t < steps is guided) and τ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuidanceSetting {
    /// Weight of ℓ_pc.
    pub w_pc: f64,
    /// Weight of ℓ_pen.
    pub w_pen: f64,
    /// Weight of ℓ_mob.
    pub w_mob: f64,
    /// n_g.
    pub steps: usize,
    /// τ.
    pub tau: f64,
}

impl GuidanceSetting {
    /// The paper's weights for `terms` (base ÷ active terms).
    pub fn paper(terms: Terms, steps: usize, tau: f64) -> Self {
        GuidanceSetting::scaled(terms, [1.0; 3], steps, tau)
    }

    /// The paper's weights for `terms` times `scales` (w_pc, w_pen, w_mob), see
    /// [`GuidanceOptions::with_loss_scales`].
    pub fn scaled(terms: Terms, scales: [f64; 3], steps: usize, tau: f64) -> Self {
        let p = GuidanceOptions::paper(Vec::new(), terms).with_loss_scales(scales);
        GuidanceSetting {
            w_pc: p.w_pc,
            w_pen: p.w_pen,
            w_mob: p.w_mob,
            steps,
            tau,
        }
    }
}

/// One row to run: its block, label and guidance.
#[derive(Debug, Clone, PartialEq)]
pub struct RowSpec {
    /// Category-aware block.
    pub category_aware: bool,
    /// Row label.
    pub label: String,
    /// Guidance (None: unguided).
    pub guidance: Option<GuidanceSetting>,
}

/// Which hyper-parameter a sweep varies (supplementary material, Figs. 7–13).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SweepKind {
    /// ℓ_pc alone: n_g × w_pc.
    Pc,
    /// ℓ_pen alone: n_g × w_pen.
    Pen,
    /// ℓ_mob alone: n_g × w_mob.
    Mob,
    /// ℓ_pc alone at the base weight and the given n_g: τ.
    Tau,
}

impl SweepKind {
    /// Parse `pc`, `pen`, `mob` or `tau`.
    pub fn parse(name: &str) -> Result<Self, EngineError> {
        match name {
            "pc" => Ok(SweepKind::Pc),
            "pen" => Ok(SweepKind::Pen),
            "mob" => Ok(SweepKind::Mob),
            "tau" => Ok(SweepKind::Tau),
            other => Err(EngineError::Invalid(crate::error::Invalid {
                field: "sweep".into(),
                limit: "one of pc, pen, mob, tau".into(),
                value: other.into(),
            })),
        }
    }

    /// The lowercase name.
    pub fn name(self) -> &'static str {
        match self {
            SweepKind::Pc => "pc",
            SweepKind::Pen => "pen",
            SweepKind::Mob => "mob",
            SweepKind::Tau => "tau",
        }
    }
}

/// The rows of a sweep: per block, the unguided baseline (the paper's black NAP line), then
/// every (n_g, weight multiplier) point of the single loss — weight = base weight × multiplier
/// — or, for τ, every τ with ℓ_pc at its base weight and n_g = `default_steps`.
pub fn sweep_rows(
    kind: SweepKind,
    blocks: &[bool],
    n_gs: &[usize],
    multipliers: &[f64],
    taus: &[f64],
    default_steps: usize,
    default_tau: f64,
) -> Result<Vec<RowSpec>, EngineError> {
    let bad = |field: &str, limit: &str, value: String| {
        Err(EngineError::Invalid(crate::error::Invalid {
            field: field.into(),
            limit: limit.into(),
            value,
        }))
    };
    if kind == SweepKind::Tau {
        if taus.is_empty() {
            return bad("sweep_tau", "at least one value", "none".into());
        }
    } else {
        if n_gs.is_empty() {
            return bad("sweep_ng", "at least one value", "none".into());
        }
        if let Some(m) = multipliers.iter().find(|m| !(m.is_finite() && **m > 0.0)) {
            return bad("sweep_weights", "finite multipliers > 0", m.to_string());
        }
        if multipliers.is_empty() {
            return bad("sweep_weights", "at least one value", "none".into());
        }
    }
    let single = |pc, pen, mob| Terms { pc, pen, mob };
    let mut rows = Vec::new();
    for &aware in blocks {
        rows.push(RowSpec {
            category_aware: aware,
            label: "uncond".into(),
            guidance: None,
        });
        match kind {
            SweepKind::Tau => {
                for &tau in taus {
                    rows.push(RowSpec {
                        category_aware: aware,
                        label: format!("pc τ={}", short(tau)),
                        guidance: Some(GuidanceSetting::paper(
                            single(true, false, false),
                            default_steps,
                            tau,
                        )),
                    });
                }
            }
            _ => {
                let terms = single(
                    kind == SweepKind::Pc,
                    kind == SweepKind::Pen,
                    kind == SweepKind::Mob,
                );
                let base = GuidanceSetting::paper(terms, default_steps, default_tau);
                for &n_g in n_gs {
                    for &m in multipliers {
                        let g = GuidanceSetting {
                            w_pc: base.w_pc * m,
                            w_pen: base.w_pen * m,
                            w_mob: base.w_mob * m,
                            steps: n_g,
                            ..base
                        };
                        let w = short(g.w_pc + g.w_pen + g.w_mob);
                        rows.push(RowSpec {
                            category_aware: aware,
                            label: format!("{} n_g={n_g} w={w}", kind.name()),
                            guidance: Some(g),
                        });
                    }
                }
            }
        }
    }
    Ok(rows)
}

/// A number with at most four decimals and no trailing zeros (row labels).
fn short(v: f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

/// Run arbitrary rows (Table 1 variants or sweep points) over every cloud and sample.
#[allow(clippy::too_many_arguments)]
pub fn run_rows(
    denoiser: &Denoiser,
    decoder: &LatentSdfDecoder,
    codebook: Option<&Codebook>,
    scales: &FeatureScales,
    schedule: &Schedule,
    clouds: &[Cloud],
    opts: &TableOptions,
    specs: &[RowSpec],
    on_sample: &mut dyn FnMut(usize, usize),
) -> Result<Vec<TableRow>, EngineError> {
    if opts.samples_per_cloud == 0 {
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: "samples_per_cloud".into(),
            limit: "at least 1".into(),
            value: "0".into(),
        }));
    }
    let specs: Vec<&RowSpec> = specs
        .iter()
        .filter(|s| !s.category_aware || clouds.iter().all(|c| c.category.is_some()))
        .collect();
    let total = specs.len() * clouds.len() * opts.samples_per_cloud;
    let mut done = 0;
    let mut rows = Vec::new();
    for spec in specs {
        let aware = spec.category_aware;
        let loss_guided = spec
            .guidance
            .is_some_and(|g| weights_active(g.w_pc, g.w_pen, g.w_mob));
        let category_weight = category_guidance(opts.category_guidance, loss_guided);
        let category_below = category_guidance_below(opts.category_guidance_below, loss_guided);
        {
            let started = std::time::Instant::now();
            let mut values: [Vec<f64>; 5] = Default::default();
            let mut per_cloud: [Vec<f64>; 2] = Default::default();
            let mut id_gt = Vec::new();
            let mut diverged = 0;
            let mut per_sample = Vec::new();
            for (c, cloud) in clouds.iter().enumerate() {
                let refs = opts.references.get(c).map(Vec::as_slice).unwrap_or(&[]);
                let mut generated: Vec<StateClouds> = Vec::new();
                let guidance = spec.guidance.map(|s| GuidanceOptions {
                    points: cloud.points.clone(),
                    w_pc: s.w_pc,
                    w_pen: s.w_pen,
                    w_mob: s.w_mob,
                    cameras: Vec::new(),
                    w_free: 0.0,
                    steps: s.steps,
                    tau: s.tau,
                    max_step: opts.max_step,
                    refine_steps: opts.refine_steps,
                    refine_physics_steps: opts.refine_physics_steps,
                });
                for k in 0..opts.samples_per_cloud {
                    let seed = opts
                        .seed
                        .wrapping_add(((opts.first_cloud + c) * opts.samples_per_cloud + k) as u64);
                    let sample_started = std::time::Instant::now();
                    let category = if aware { cloud.category } else { None };
                    let req = GenerateRequest {
                        seed,
                        samples: 1,
                        category,
                        meshing: opts.meshing,
                        guidance: guidance.clone(),
                        sampler: opts.sampler,
                        steps: opts.steps,
                        retrieval: match category {
                            Some(_) => opts.retrieval,
                            None => opts.retrieval.without_category(),
                        },
                        category_guidance: category_weight,
                        category_guidance_below: Some(category_below),
                        joint_motion: opts.joint_motion,
                        ..Default::default()
                    };
                    let shapes = PartShapes {
                        decoder,
                        field: Some(decoder as &dyn SdfField),
                        codebook,
                    };
                    match generate_with(denoiser, &shapes, scales, schedule, &req, &mut |_| {
                        ControlFlow::Continue(())
                    }) {
                        Ok(out) => {
                            let g = &out[0];
                            let m = metrics(
                                decoder,
                                &g.raw,
                                &g.object,
                                &g.meshes,
                                &cloud.points,
                                g.scale,
                                g.seed,
                            );
                            let all = [m.e_pc, m.d_pc, m.e_pen, m.e_mob, m.o_mesh];
                            for (slot, v) in values.iter_mut().zip(all) {
                                slot.push(v);
                            }
                            // A sample without any mesh triangles has no surface to compare;
                            // it stays out of the generative metrics and ID_gt (it still
                            // counts above).
                            let sc = if refs.is_empty() {
                                None
                            } else {
                                state_clouds(&g.object, &g.meshes, &opts.id, g.seed).ok()
                            };
                            let gt = match (&sc, opts.scanned.get(c)) {
                                (Some(sc), Some(true)) => {
                                    Some(instantiation_distance(sc, &refs[0]))
                                }
                                _ => None,
                            };
                            id_gt.extend(gt);
                            per_sample.push(SampleRecord {
                                cloud: cloud.id.clone(),
                                seed,
                                metrics: Some(all),
                                id_gt: gt,
                                seconds: sample_started.elapsed().as_secs_f64(),
                            });
                            generated.extend(sc);
                        }
                        Err(EngineError::Diverged { .. }) => {
                            diverged += 1;
                            per_sample.push(SampleRecord {
                                cloud: cloud.id.clone(),
                                seed,
                                metrics: None,
                                id_gt: None,
                                seconds: sample_started.elapsed().as_secs_f64(),
                            });
                        }
                        Err(e) => return Err(e),
                    }
                    done += 1;
                    on_sample(done, total);
                }
                if let Some(m) = cloud_metrics(&generated, refs)? {
                    per_cloud[0].push(m.mmd);
                    per_cloud[1].push(m.one_nna);
                }
            }
            let n = values[0].len();
            rows.push(TableRow {
                category_aware: aware,
                variant: spec.label.clone(),
                guidance: spec.guidance,
                category_guidance: aware.then_some((category_weight, category_below)),
                e_pc: median(&values[0]),
                d_pc: median(&values[1]),
                e_pen: median(&values[2]),
                e_mob: median(&values[3]),
                e_pen_mean: mean(&values[2]),
                e_mob_mean: mean(&values[3]),
                pen_share: positive_share(&values[2]),
                mob_share: positive_share(&values[3]),
                o_mesh_mean: mean(&values[4]),
                o_mesh_share: positive_share(&values[4]),
                mmd: median(&per_cloud[0]),
                one_nna: median(&per_cloud[1]),
                id_gt: median(&id_gt),
                id_gt_mean: mean(&id_gt),
                samples: n,
                diverged,
                seconds_per_sample: started.elapsed().as_secs_f64() / (n + diverged).max(1) as f64,
                per_sample,
            });
        }
    }
    Ok(rows)
}

/// MMD and 1-NNA (PointFlow order) of one cloud's samples against its references; None when
/// either set is too small (1-NNA needs two objects on each side).
pub fn cloud_metrics(
    generated: &[StateClouds],
    references: &[StateClouds],
) -> Result<Option<DistributionMetrics>, EngineError> {
    if generated.len() < 2 || references.len() < 2 {
        return Ok(None);
    }
    let quiet = |_: usize| {};
    let d_gr = distance_matrix(generated, references, false, &quiet);
    let d_gg = distance_matrix(generated, generated, true, &quiet);
    let d_rr = distance_matrix(references, references, true, &quiet);
    distribution_metrics(&d_gr, &d_gg, &d_rr, MetricOrder::PointFlow)
        .map(Some)
        .map_err(|e| {
            EngineError::Invalid(crate::error::Invalid {
                field: "references".into(),
                limit: "valid instantiation distances".into(),
                value: e.to_string(),
            })
        })
}

/// Mean of the finite values (NaN when there are none).
pub fn mean(values: &[f64]) -> f64 {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Share of the finite values that are > 0 (NaN when there are none).
pub fn positive_share(values: &[f64]) -> f64 {
    share_above(values, 0.0)
}

/// The share of the finite values above `threshold` (NaN when there are none).
pub fn share_above(values: &[f64], threshold: f64) -> f64 {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().filter(|&&x| x > threshold).count() as f64 / v.len() as f64
    }
}

/// The table as Markdown in the paper's layout ("—" where a metric could not be computed),
/// followed by physnap's extra columns: means of E_pen / E_mob / O_mesh and the share of
/// samples in which they are non-zero, then the median and mean ID_gt (the completion's
/// instantiation distance to the scanned object).
pub fn table_markdown(rows: &[TableRow]) -> String {
    let mut s = String::from(
        "| category | variant | E_pc | D_pc | E_pen | E_mob | MMD | 1-NNA | samples | diverged | s/sample | E_pen mean | E_mob mean | E_pen > 0 | E_mob > 0 | O_mesh mean | O_mesh > 0 | ID_gt | ID_gt mean |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            if r.category_aware { "yes" } else { "no" },
            r.variant,
            cell(r.e_pc),
            cell(r.d_pc),
            cell(r.e_pen),
            cell(r.e_mob),
            cell(r.mmd),
            cell(r.one_nna),
            r.samples,
            r.diverged,
            r.seconds_per_sample,
            cell(r.e_pen_mean),
            cell(r.e_mob_mean),
            percent(r.pen_share),
            percent(r.mob_share),
            cell(r.o_mesh_mean),
            percent(r.o_mesh_share),
            cell(r.id_gt),
            cell(r.id_gt_mean),
        ));
    }
    s
}

/// A share as a whole percentage, "—" when it is not finite.
fn percent(v: f64) -> String {
    if v.is_finite() {
        format!("{:.0} %", 100.0 * v)
    } else {
        "—".into()
    }
}

/// A metric with four decimals, "—" when it is not finite.
fn cell(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "—".into()
    }
}

#[cfg(test)]
mod tests;
