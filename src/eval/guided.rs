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
/// sampled with `seed`).
pub fn metrics(
    field: &dyn SdfField,
    raw: &GraphTensor,
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    points: &[[f32; 3]],
    seed: u64,
) -> GuidedMetrics {
    GuidedMetrics {
        d_pc: d_pc(meshes, points),
        o_mesh: mesh_overlap(obj, meshes, MESH_OVERLAP_SAMPLES, seed),
        ..sdf_metrics(field, raw, points)
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
        return Err(EngineError::Invalid {
            field: "variants".into(),
            limit: format!("names among {}", VARIANTS.map(|v| v.name).join(", ")),
            value: unknown.clone(),
        });
    }
    if let Some((name, v)) = ["pc", "pen", "mob"]
        .into_iter()
        .zip(opts.loss_scales)
        .find(|(_, v)| !(v.is_finite() && (0.0..=100.0).contains(v)))
    {
        return Err(EngineError::Invalid {
            field: format!("loss_scales.{name}"),
            limit: "finite, in [0, 100]".into(),
            value: v.to_string(),
        });
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
            other => Err(EngineError::Invalid {
                field: "sweep".into(),
                limit: "one of pc, pen, mob, tau".into(),
                value: other.into(),
            }),
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
        Err(EngineError::Invalid {
            field: field.into(),
            limit: limit.into(),
            value,
        })
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
        return Err(EngineError::Invalid {
            field: "samples_per_cloud".into(),
            limit: "at least 1".into(),
            value: "0".into(),
        });
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
        .map_err(|e| EngineError::Invalid {
            field: "references".into(),
            limit: "valid instantiation distances".into(),
            value: e.to_string(),
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
mod tests {
    use super::*;
    use crate::engine::guidance::BoxField;
    use crate::graph::node_ch;
    use crate::mesh::primitives;

    fn part(g: &mut GraphTensor, i: usize, b: [f32; 3], t: [f32; 3]) {
        let kappa = 2.0 * (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
        let row = g.node_mut(i);
        row[node_ch::EXIST] = 1.0;
        row[node_ch::BOX..node_ch::BOX + 3].copy_from_slice(&b);
        row[node_ch::CENTER..node_ch::CENTER + 3].copy_from_slice(&t);
        for k in 0..3 {
            row[node_ch::LATENT + k] = b[k] / kappa;
        }
    }

    #[test]
    fn metrics_of_exact_boxes() {
        let field = BoxField { latent: 8 };
        let mut g = GraphTensor::empty();
        part(&mut g, 0, [0.5, 0.5, 0.5], [0.0, 0.0, 0.0]);
        part(&mut g, 1, [0.3, 0.3, 0.3], [0.7, 0.0, 0.0]); // overlaps part 0 by 0.1 in x
        // A weak third slot does not count.
        g.node_mut(2)[node_ch::EXIST] = 0.3;
        let pts: Vec<[f32; 3]> = vec![[0.0, 0.0, 0.6], [0.0, 0.0, 0.5], [1.0, 0.0, 0.0]];
        let m = sdf_metrics(&field, &g, &pts);
        // 0.1² for the first point, 0 for the others.
        assert!((m.e_pc - 0.01 / 3.0).abs() < 1e-5, "E_pc {}", m.e_pc);
        assert!(m.e_pen > 0.0, "overlap: E_pen {}", m.e_pen);
        // The MST joins the two slots through the row's default "no edge" values (zero ranges):
        // every state is the rest state, so E_mob (one ordering × 2, mean over states) is the
        // same integral over the same box as E_pen.
        assert!(
            (m.e_mob - m.e_pen).abs() < 1e-4 * m.e_pen,
            "E_mob {} vs E_pen {}",
            m.e_mob,
            m.e_pen
        );
        // Apart: no penetration either way.
        let mut apart = g.clone();
        apart.node_mut(1)[node_ch::CENTER] = 1.0;
        let ma = sdf_metrics(&field, &apart, &pts);
        assert_eq!((ma.e_pen, ma.e_mob), (0.0, 0.0));
        // D_pc against the box meshes.
        let mut mesh = TriMesh {
            positions: Vec::new(),
            triangles: Vec::new(),
        };
        let cube = crate::shape::Primitive::Cuboid {
            center: nalgebra::Vector3::zeros(),
            half_extents: nalgebra::Vector3::new(0.5, 0.5, 0.5),
        };
        primitives::append_primitive(&mut mesh, &cube, &nalgebra::Vector3::zeros());
        let meshes = vec![mesh];
        let d = d_pc(&meshes, &[[0.0, 0.0, 0.6], [0.0, 0.0, 0.5]]);
        assert!((d - 0.05).abs() < 1e-6, "D_pc {d}");
        assert!(d_pc(&[], &pts).is_nan());
        assert_eq!(median(&[3.0, f64::NAN, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        // Mean and share see the rare overlaps a median of 0 hides.
        let pen = [0.0, 0.0, 0.0, 8.0, f64::NAN];
        assert_eq!(median(&pen), 0.0);
        assert_eq!(mean(&pen), 2.0);
        assert_eq!(positive_share(&pen), 0.25);
        assert!(mean(&[]).is_nan() && positive_share(&[f64::NAN]).is_nan());
    }

    #[test]
    fn mesh_overlap_measures_buried_surface_at_rest_and_in_motion() {
        use crate::object::{Joint, JointKind, Part};
        use crate::shape::PartShape;
        use nalgebra::Vector3;
        let meshes_of = |obj: &ArticulatedObject| -> Vec<TriMesh> {
            obj.parts
                .iter()
                .map(|p| primitives::part_primitive_mesh(p).expect("primitive part"))
                .collect()
        };
        // Two unit cubes, the second 0.3 deep in the first, sliding out along x by 0.6 over
        // its range. At f = 0 and 1/4 one face of each lies inside the other (area 0.99² each
        // beyond δ = 5 mm of the shared side faces) out of 12; at f = 1/2 they touch; then
        // apart. Mean over the 5 states: 2 · 2 · 0.99² / 12 / 5.
        let cube = |name: &str, x: f64| Part {
            name: name.into(),
            half_extents: Vector3::new(0.5, 0.5, 0.5),
            center: Vector3::new(x, 0.0, 0.0),
            shape: PartShape::Box,
        };
        let slide = ArticulatedObject {
            name: "cubes".into(),
            category: None,
            parts: vec![cube("a", 0.0), cube("b", 0.7)],
            joints: vec![Joint {
                parent: 0,
                child: 1,
                kind: JointKind::Prismatic,
                axis: Vector3::x(),
                origin: nalgebra::Point3::origin(),
                revolute: [0.0, 0.0],
                prismatic: [0.0, 0.6],
            }],
        };
        slide.validate().unwrap();
        let expected = 4.0 * 0.99f64.powi(2) / 12.0 / 5.0;
        let o = mesh_overlap(&slide, &meshes_of(&slide), 4096, 3);
        assert!((o - expected).abs() < 0.01, "O_mesh {o} vs {expected}");
        // Seeded: the same call gives the same value.
        assert_eq!(o, mesh_overlap(&slide, &meshes_of(&slide), 4096, 3));
        // The example cabinet never interpenetrates, at rest or moving.
        let cabinet = crate::fixtures::cabinet();
        assert_eq!(mesh_overlap(&cabinet, &meshes_of(&cabinet), 512, 1), 0.0);
        // Its door swinging inwards instead hits the back panel, though it is clear at rest.
        let mut inward = cabinet.clone();
        let door = inward.joints.iter_mut().find(|j| j.child == 1).unwrap();
        door.revolute = [-1.9, 0.0];
        let o = mesh_overlap(&inward, &meshes_of(&inward), 512, 1);
        assert!(o > 0.0, "inward door: O_mesh {o}");
        let rest_only = ArticulatedObject {
            joints: inward
                .joints
                .iter()
                .map(|j| Joint {
                    revolute: [0.0, 0.0],
                    prismatic: [0.0, 0.0],
                    ..j.clone()
                })
                .collect(),
            ..inward.clone()
        };
        assert_eq!(
            mesh_overlap(&rest_only, &meshes_of(&rest_only), 512, 1),
            0.0
        );
        // Meshes that do not match the parts, or no area at all: no value.
        assert!(mesh_overlap(&slide, &meshes_of(&slide)[..1], 64, 0).is_nan());
        let empty = vec![TriMesh::default(), TriMesh::default()];
        assert!(mesh_overlap(&slide, &empty, 64, 0).is_nan());
    }

    #[test]
    fn the_table_has_the_paper_layout_and_counts_every_sample() {
        use crate::model::denoiser::DenoiserConfig;
        use crate::model::shape_prior::{ShapeDecoder, ShapePriorConfig};
        let dev = crate::model::cpu();
        let denoiser = Denoiser::new(
            &DenoiserConfig {
                width: 16,
                layers: 1,
                head_channels: 8,
                node_head_hidden: vec![16],
                edge_head_hidden: vec![16],
                categories: 3,
                ..DenoiserConfig::default()
            },
            &dev,
        )
        .unwrap();
        let shape = ShapeDecoder::new(
            &ShapePriorConfig {
                decoder_hidden: 16,
                decoder_blocks: 1,
                ..ShapePriorConfig::default()
            },
            &mut crate::data::rng::Rng::new(0),
            &dev,
        );
        let decoder = LatentSdfDecoder::new(&shape);
        let table = |clouds: &[Cloud], opts: &TableOptions| {
            guided_table(
                &denoiser,
                &decoder,
                None,
                &FeatureScales::default(),
                &Schedule::default(),
                clouds,
                opts,
                &mut |_, _| {},
            )
        };
        let clouds = vec![Cloud {
            id: "c0".into(),
            category: Some(1),
            points: vec![[0.0, 0.0, 0.5], [0.2, 0.1, 0.3], [-0.1, 0.2, 0.8]],
        }];
        let opts = TableOptions {
            samples_per_cloud: 1,
            seed: 0,
            first_cloud: 0,
            category_aware: vec![false, true],
            variants: Vec::new(),
            guided_steps: 1000,
            tau: 1000.0,
            loss_scales: [1.0; 3],
            max_step: Some(0.05),
            refine_steps: 0,
            refine_physics_steps: 0,
            sampler: Sampler::Ddim { eta: 0.0 },
            steps: 4,
            meshing: MeshingOptions { resolution: 8 },
            references: Vec::new(),
            scanned: Vec::new(),
            id: IdOptions::default(),
            retrieval: Retrieval::Off,
            category_guidance: None,
            category_guidance_below: None,
            joint_motion: JointMotion::Screw,
        };
        let mut calls = 0;
        let rows = guided_table(
            &denoiser,
            &decoder,
            None,
            &FeatureScales::default(),
            &Schedule::default(),
            &clouds,
            &opts,
            &mut |done, total| {
                calls += 1;
                assert_eq!((done, total), (calls, 10));
            },
        )
        .unwrap();
        let labels: Vec<(bool, &str)> = rows
            .iter()
            .map(|r| (r.category_aware, r.variant.as_str()))
            .collect();
        let names: Vec<&str> = VARIANTS.iter().map(|v| v.name).collect();
        let want: Vec<(bool, &str)> = [false, true]
            .iter()
            .flat_map(|&a| names.iter().map(move |&n| (a, n)))
            .collect();
        assert_eq!(labels, want);
        // Unset, the category guidance is each row's default: none under loss guidance, w = 2
        // below t = 500 for the unguided row; category-unaware rows have none to run.
        for r in &rows {
            let want = match (r.category_aware, r.guidance.is_some()) {
                (false, _) => None,
                (true, true) => Some((0.0, 1000)),
                (true, false) => Some((2.0, 500)),
            };
            assert_eq!(r.category_guidance, want, "{}", r.variant);
        }
        assert!(rows.iter().all(|r| r.samples + r.diverged == 1));
        // Every sample is on record with its cloud and seed, diverged ones without metrics.
        for r in &rows {
            assert_eq!(r.per_sample.len(), 1, "{r:?}");
            let s = &r.per_sample[0];
            assert_eq!((s.cloud.as_str(), s.seed), ("c0", 0));
            assert_eq!(s.metrics.is_none(), r.diverged == 1);
            if let Some(m) = s.metrics {
                assert_eq!(m[0], r.e_pc, "a single sample is its own median");
                // O_mesh is on record and is the row's mean (NaN only without mesh area).
                assert!(
                    m[4] == r.o_mesh_mean || (m[4].is_nan() && r.o_mesh_mean.is_nan()),
                    "{r:?}"
                );
            }
        }
        let md = table_markdown(&rows);
        assert_eq!(md.lines().count(), 12);
        assert!(md.contains("| yes | pc+pen+mob |"), "{md}");
        assert!(md.lines().all(|l| l.matches('|').count() == 20), "{md}");
        assert!(
            md.contains("| O_mesh mean | O_mesh > 0 | ID_gt | ID_gt mean |"),
            "{md}"
        );
        // Without the scanned object there is no ID_gt.
        assert!(rows.iter().all(|r| r.id_gt.is_nan()), "{rows:?}");
        assert!(
            rows.iter()
                .flat_map(|r| &r.per_sample)
                .all(|s| s.id_gt.is_none())
        );

        // With the scanned object as the cloud's first reference, every sample with a surface
        // records its instantiation distance to it, and the row reports their median and mean.
        // A slice of the test set (first_cloud) keeps the seeds a full run gives its clouds.
        let id = IdOptions {
            states: 2,
            points: 64,
        };
        let cab = crate::fixtures::cabinet();
        let cab_meshes =
            crate::mesh::mesh_parts(&cab, None, &MeshingOptions { resolution: 16 }).unwrap();
        let gt = state_clouds(&cab, &cab_meshes, &id, 7).unwrap();
        let with_gt = TableOptions {
            category_aware: vec![false],
            variants: vec!["uncond".into()],
            samples_per_cloud: 2,
            first_cloud: 3,
            references: vec![vec![gt.clone(), gt]],
            scanned: vec![true],
            id,
            ..opts.clone()
        };
        let rows = table(&clouds, &with_gt).unwrap();
        let seeds: Vec<u64> = rows[0].per_sample.iter().map(|s| s.seed).collect();
        assert_eq!(seeds, [6, 7], "cloud 3 of a full run, 2 samples per cloud");
        let ids: Vec<f64> = rows[0].per_sample.iter().filter_map(|s| s.id_gt).collect();
        assert!(!ids.is_empty(), "{rows:?}");
        assert!(ids.iter().all(|d| d.is_finite() && *d > 0.0), "{ids:?}");
        assert_eq!(rows[0].id_gt, median(&ids));
        assert_eq!(rows[0].id_gt_mean, mean(&ids));
        // The same references, not marked as the scanned object: no ID_gt.
        let rows = table(
            &clouds,
            &TableOptions {
                scanned: vec![false],
                ..with_gt
            },
        )
        .unwrap();
        assert!(rows[0].per_sample.iter().all(|s| s.id_gt.is_none()));
        assert!(rows[0].id_gt.is_nan());
        // A cloud without a category: the category-aware block is left out.
        let anon = vec![Cloud {
            category: None,
            ..clouds[0].clone()
        }];
        let rows = table(
            &anon,
            &TableOptions {
                category_aware: vec![true],
                ..opts.clone()
            },
        )
        .unwrap();
        assert!(rows.is_empty());
        // A subset of the variants, in the table's order; an unknown name is refused.
        let rows = table(
            &clouds,
            &TableOptions {
                category_aware: vec![false],
                variants: vec!["uncond".into(), "pc".into()],
                ..opts.clone()
            },
        )
        .unwrap();
        let names: Vec<&str> = rows.iter().map(|r| r.variant.as_str()).collect();
        assert_eq!(names, ["pc", "uncond"]);
        let err = table(
            &clouds,
            &TableOptions {
                variants: vec!["pc+penn".into()],
                ..opts.clone()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("variants") && err.contains("pc+penn"), "{err}");
        // Loss scales multiply the paper's weights of every guided row; a bad one is refused
        // naming the term, the limit and the value.
        let scaled = TableOptions {
            loss_scales: [1.0, 3.0, 0.5],
            ..opts.clone()
        };
        let specs = table_rows(&scaled).unwrap();
        let full = specs.iter().find(|s| s.label == "pc+pen+mob").unwrap();
        let g = full.guidance.unwrap();
        assert_eq!((g.w_pc, g.w_pen, g.w_mob), (15.0, 2.0, 1.0 / 3.0));
        let pc = specs.iter().find(|s| s.label == "pc").unwrap();
        assert_eq!(pc.guidance.unwrap().w_pc, 45.0);
        assert!(
            specs.iter().any(|s| s.guidance.is_none()),
            "uncond stays unguided"
        );
        let err = table_rows(&TableOptions {
            loss_scales: [1.0, -2.0, 1.0],
            ..opts.clone()
        })
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("loss_scales.pen") && err.contains("[0, 100]") && err.contains("-2"),
            "{err}"
        );

        // A sweep: the baseline plus every (n_g, weight) point, each run with its own guidance.
        let specs = sweep_rows(
            SweepKind::Pen,
            &[false],
            &[2, 1000],
            &[0.5, 4.0],
            &[],
            500,
            1000.0,
        )
        .unwrap();
        let rows = run_rows(
            &denoiser,
            &decoder,
            None,
            &FeatureScales::default(),
            &Schedule::default(),
            &clouds,
            &opts,
            &specs,
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(rows.len(), 5);
        assert_eq!(rows[0].guidance, None);
        assert_eq!(rows[4].variant, "pen n_g=1000 w=8");
        let g = rows[4].guidance.unwrap();
        assert_eq!((g.w_pc, g.w_pen, g.w_mob, g.steps), (0.0, 8.0, 0.0, 1000));
        assert!(rows.iter().all(|r| r.samples + r.diverged == 1));
    }

    #[test]
    fn sweeps_cover_the_grid_and_refuse_bad_values() {
        let rows = sweep_rows(
            SweepKind::Pc,
            &[false, true],
            &[100, 500],
            &[0.1, 1.0, 10.0],
            &[],
            500,
            1000.0,
        )
        .unwrap();
        assert_eq!(rows.len(), 2 * (1 + 2 * 3));
        assert!(rows[..7].iter().all(|r| !r.category_aware));
        let w: Vec<f64> = rows[1..4]
            .iter()
            .map(|r| r.guidance.unwrap().w_pc)
            .collect();
        assert!((w[0] - 4.5).abs() < 1e-12 && w[1] == 45.0 && (w[2] - 450.0).abs() < 1e-9);
        assert_eq!(rows[1].label, "pc n_g=100 w=4.5");
        assert_eq!(short(0.3 * 45.0), "13.5");
        let tau = sweep_rows(
            SweepKind::Tau,
            &[false],
            &[],
            &[],
            &[100.0, 1000.0],
            500,
            1.0,
        )
        .unwrap();
        let t: Vec<(f64, f64, usize)> = tau[1..]
            .iter()
            .map(|r| r.guidance.map(|g| (g.tau, g.w_pc, g.steps)).unwrap())
            .collect();
        assert_eq!(t, [(100.0, 45.0, 500), (1000.0, 45.0, 500)]);
        let e = sweep_rows(SweepKind::Mob, &[false], &[500], &[0.0], &[], 500, 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("sweep_weights") && e.contains('0'), "{e}");
        let e = SweepKind::parse("penn").unwrap_err().to_string();
        assert!(
            e.contains("sweep") && e.contains("penn") && e.contains("tau"),
            "{e}"
        );
    }

    #[test]
    fn per_cloud_generative_metrics_see_which_set_matches_the_references() {
        use crate::mesh::mesh_parts;
        // 256 points: resampling noise (≈ 0.015 here) well under half the cabinet-for-eight-part
        // mismatch (≈ 0.04).
        let id = IdOptions {
            states: 2,
            points: 256,
        };
        let prepared = |obj: &crate::object::ArticulatedObject, seed: u64| {
            let m = mesh_parts(obj, None, &MeshingOptions { resolution: 16 }).unwrap();
            state_clouds(obj, &m, &id, seed).unwrap()
        };
        let cab = crate::fixtures::cabinet();
        let eight = crate::fixtures::eight_part();
        let refs = vec![prepared(&cab, 1), prepared(&eight, 2)];
        // Re-sampled copies of the references match them far better than two cabinets do.
        let good = vec![prepared(&cab, 3), prepared(&eight, 4)];
        let poor = vec![prepared(&cab, 5), prepared(&cab, 6)];
        let g = cloud_metrics(&good, &refs).unwrap().unwrap();
        let p = cloud_metrics(&poor, &refs).unwrap().unwrap();
        assert!(g.mmd < p.mmd / 2.0, "good {g:?} vs poor {p:?}");
        assert!(g.cov > p.cov, "good {g:?} vs poor {p:?}");
        assert!(g.one_nna < p.one_nna, "good {g:?} vs poor {p:?}");
        // Fewer than two objects on a side: no metric rather than a misleading one.
        assert!(cloud_metrics(&good[..1], &refs).unwrap().is_none());
        assert!(cloud_metrics(&good, &[]).unwrap().is_none());
    }
}
