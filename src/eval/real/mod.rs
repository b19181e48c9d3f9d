//! `eval real`: generation on every scan of a benchmark set of real (or procedural) assets,
//! scored against the asset itself with the metrics of real-scans.md §3.
//!
//! Why it exists: "works on real scans" has to be one number computed one way. [`metrics`]
//! defines the per-object metrics; this module draws the samples of one job (one scan, one
//! row), picks the `best` one as `generate` ranks them (lowest D_pc, ties by sample index),
//! and sums jobs into per-object, per-category and overall figures ([`summarise`]). Reading
//! the scan set, exporting URDFs, calling the MuJoCo check and writing reports is the CLI's and
//! `io`'s part; nothing here touches files or serialisation.
//!
//! Rows: `prior` (unguided, one sample), `guided` (`generate --points`'s defaults, one sample)
//! and `best-of-N` (the same guidance, N samples, the best by the ranking score of
//! `eval::rank`). Sample k of a scan's guided draws has seed `seed + k` in both guided rows, so
//! `guided` is `best-of-N`'s sample 0 and is drawn once. Each row runs with the scan's
//! category (`category_aware`) or without.
//!
//! Failed jobs (every sample diverged or failed, no surface, an export MuJoCo could not load)
//! count as misses in every share; in the Chamfer median a failed job counts as +∞.

pub mod frame;
pub mod metrics;
pub mod report;

use std::ops::ControlFlow;
use std::time::Instant;

use crate::engine::EngineError;
use crate::engine::generate::{GenerateRequest, Generated, PartShapes, generate_with};
use crate::engine::schedule::Schedule;
use crate::graph::FeatureScales;
use crate::mesh::TriMesh;
use crate::model::denoiser::Denoiser;
use crate::object::{ArticulatedObject, JointKind};

pub use metrics::{JointMatch, ObjectMetrics, object_metrics};

/// Errors of the real-scan evaluation.
#[derive(Debug, thiserror::Error)]
pub enum RealError {
    /// An option or input broke a limit.
    #[error("invalid {0}")]
    Invalid(crate::error::Invalid),
    /// Generation failed for a reason that is not the job's (bad settings).
    #[error(transparent)]
    Engine(#[from] EngineError),
}

/// The ground truth of a scan: the asset at rest, object frame.
#[derive(Debug, Clone)]
pub struct GtObject {
    /// The asset (fixed-joined links may be merged or not; [`metrics::rigid_parts`] counts them
    /// once either way).
    pub object: ArticulatedObject,
    /// Its part meshes at rest, object frame.
    pub meshes: Vec<TriMesh>,
}

impl GtObject {
    /// Movable joints.
    pub fn movable_joints(&self) -> usize {
        self.object
            .joints
            .iter()
            .filter(|j| j.kind != JointKind::Fixed)
            .count()
    }

    /// Revolute joints (the pivot error's population).
    pub fn revolute_joints(&self) -> usize {
        self.object
            .joints
            .iter()
            .filter(|j| j.kind == JointKind::Revolute)
            .count()
    }
}

/// A row of the report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    /// Unguided prior, one sample.
    Prior,
    /// Guided, one sample.
    Guided,
    /// Guided, the best of this many samples by D_pc.
    BestOf(usize),
}

impl RowKind {
    /// Key in files and flags: `prior`, `guided`, `best-of-N`.
    pub fn key(self) -> String {
        match self {
            RowKind::Prior => "prior".into(),
            RowKind::Guided => "guided".into(),
            RowKind::BestOf(n) => format!("best-of-{n}"),
        }
    }

    /// Samples drawn for this row.
    pub fn samples(self) -> usize {
        match self {
            RowKind::Prior | RowKind::Guided => 1,
            RowKind::BestOf(n) => n,
        }
    }
}

/// One row: its kind and whether the scan's category is given to the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RowSpec {
    /// Which samples.
    pub kind: RowKind,
    /// Category-conditioned (the scan's category) or not.
    pub category_aware: bool,
}

impl RowSpec {
    /// Key: the kind's, with `+category` when category-aware.
    pub fn key(&self) -> String {
        if self.category_aware {
            format!("{}+category", self.kind.key())
        } else {
            self.kind.key()
        }
    }
}

/// One drawn sample of a job.
#[derive(Debug, Clone)]
pub struct JobSample {
    /// Sample index within the job's draws.
    pub index: usize,
    /// Its seed.
    pub seed: u64,
    /// D_pc of the sample (NaN without surface).
    pub d_pc: f64,
    /// The ranking score (`eval::rank`; NaN without surface).
    pub score: f64,
    /// Wall time of this sample (sampling + meshing + D_pc), seconds.
    pub seconds: f64,
    /// The sample, or why there is none (diverged, projection failed, ...).
    pub outcome: Result<Generated, EngineError>,
}

/// Draw `n` samples of `req` one by one (sample k with seed `req.seed + k`, as `generate`),
/// each scored by D_pc against `points`. A sample that fails is kept as a failure; errors that
/// would fail every sample alike (bad settings, a stop request) are returned.
#[allow(clippy::too_many_arguments)]
pub fn draw_samples(
    denoiser: &Denoiser,
    shapes: &PartShapes,
    scales: &FeatureScales,
    schedule: &Schedule,
    req: &GenerateRequest,
    n: usize,
    points: &[[f32; 3]],
    on_sample: &mut dyn FnMut(usize),
) -> Result<Vec<JobSample>, RealError> {
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let started = Instant::now();
        let one = GenerateRequest {
            seed: req.seed.wrapping_add(k as u64),
            samples: 1,
            ..req.clone()
        };
        let r = generate_with(denoiser, shapes, scales, schedule, &one, &mut |_| {
            ControlFlow::Continue(())
        });
        let (outcome, d): (_, (f64, f64)) = match r {
            Ok(mut v) if !v.is_empty() => {
                let mut g = v.remove(0);
                g.index = k;
                g.object.name = format!("sample_{k:03}");
                // The sample is canonical: rank it against the scan moved there.
                let canonical = crate::engine::generate::canonical_guidance(req);
                let (points, cameras) = match &canonical {
                    Some(o) => (&o.points[..], &o.cameras[..]),
                    None => (points, &[][..]),
                };
                let terms = crate::eval::rank::sample_terms(
                    &g.object, &g.meshes, points, cameras, one.seed,
                );
                (Ok(g), (terms.d_pc, terms.score()))
            }
            Ok(_) => (
                Err(EngineError::Invalid(crate::error::Invalid::new(
                    "sample",
                    "an object",
                    "none returned",
                ))),
                (f64::NAN, f64::NAN),
            ),
            Err(
                e @ (EngineError::Invalid(crate::error::Invalid { .. })
                | EngineError::Stopped { .. }),
            ) => {
                // A projection failure is the sample's; other invalid options are the run's.
                if matches!(&e, EngineError::Invalid(crate::error::Invalid { field, .. }) if field == "sample")
                {
                    (Err(e), (f64::NAN, f64::NAN))
                } else {
                    return Err(e.into());
                }
            }
            Err(e) => (Err(e), (f64::NAN, f64::NAN)),
        };
        out.push(JobSample {
            index: k,
            seed: one.seed,
            d_pc: d.0,
            score: d.1,
            seconds: started.elapsed().as_secs_f64(),
            outcome,
        });
        on_sample(k + 1);
    }
    Ok(out)
}

/// The `best` of the first `n` samples as `generate`'s ranking.json marks it: lowest score
/// (non-finite last), ties by index; None when none of them produced an object.
pub fn best_of(samples: &[JobSample], n: usize) -> Option<usize> {
    let key = |s: &JobSample| {
        if s.score.is_finite() {
            s.score
        } else {
            f64::INFINITY
        }
    };
    samples
        .iter()
        .take(n)
        .filter(|s| s.outcome.is_ok())
        .min_by(|a, b| key(a).total_cmp(&key(b)).then(a.index.cmp(&b.index)))
        .map(|s| s.index)
}

/// MuJoCo's verdict on an exported URDF (scripts/sim_check.py).
#[derive(Debug, Clone, PartialEq)]
pub struct SimResult {
    /// MuJoCo compiled the URDF with its meshes.
    pub compiled: bool,
    /// Compiled, and no contact between two bodies deeper than 5 mm at rest or in the sweeps.
    pub clean: bool,
    /// Deepest contact at rest (m).
    pub rest_depth: Option<f64>,
    /// Deepest contact over the joint sweeps (m).
    pub sweep_depth: Option<f64>,
    /// The bodies of the deepest contact.
    pub worst_bodies: Vec<String>,
    /// MuJoCo's error, when it refused the file.
    pub error: Option<String>,
}

/// The native check ([`crate::sim`]) of a job's export: on the collision pieces export wrote,
/// and on the convex hull of each whole visual mesh (what an engine makes of a part without
/// collision pieces).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NativeSim {
    /// Clean on the exported collision pieces.
    pub clean: bool,
    /// Deepest contact on them (m).
    pub worst_depth: f64,
    /// Clean on the whole meshes' hulls.
    pub hulls_clean: bool,
    /// Deepest contact on the hulls (m).
    pub hulls_worst_depth: f64,
}

/// One job: one scan, one row.
#[derive(Debug, Clone, PartialEq)]
pub struct JobResult {
    /// The row.
    pub row: RowSpec,
    /// Samples drawn.
    pub samples: usize,
    /// The best sample's index and seed (None: the job failed).
    pub best: Option<(usize, u64)>,
    /// The best sample's D_pc.
    pub d_pc: f64,
    /// Why the job failed (None: it produced an object).
    pub error: Option<String>,
    /// The metrics of the best sample (None: failed).
    pub metrics: Option<ObjectMetrics>,
    /// MuJoCo's check of its export (None: failed before, or not run).
    pub sim: Option<SimResult>,
    /// The native check of its export (None: failed before, or a result file from before it).
    pub native: Option<NativeSim>,
    /// Wall time of the job (its samples, export and metrics), seconds.
    pub seconds: f64,
}

/// Every job of one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanResult {
    /// Scan id.
    pub scan: String,
    /// The scanned object's id.
    pub object: String,
    /// Its category.
    pub category: Option<String>,
    /// View index of the scan.
    pub view: usize,
    /// Camera position, canonical frame (when recorded).
    pub camera: Option<[f64; 3]>,
    /// Points of the scan.
    pub points: usize,
    /// GT movable joints (the axis share's population, misses included).
    pub gt_joints: usize,
    /// GT revolute joints (the pivot share's population).
    pub gt_revolute: usize,
    /// With `eval real --frame auto`: how far the frame estimated for the moved scan was from
    /// the truth (None: canonical input, or the estimate refused the scan).
    pub frame_error: Option<frame::FrameError>,
    /// One per row.
    pub jobs: Vec<JobResult>,
}

/// Figures of a set of jobs (one row; one object, one category or all).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Summary {
    /// Jobs.
    pub jobs: usize,
    /// Jobs that failed.
    pub failed: usize,
    /// Jobs with the part count exact.
    pub parts_exact: usize,
    /// Jobs with the movable joint types exact.
    pub types_exact: usize,
    /// GT movable joints.
    pub gt_joints: usize,
    /// Of those, axes within 10°.
    pub axis_ok: usize,
    /// GT revolute joints.
    pub gt_revolute: usize,
    /// Of those, with a generated revolute joint to match.
    pub revolute_matched: usize,
    /// Of those, pivots within 0.05 diagonals.
    pub pivot_ok: usize,
    /// Median pivot error of the matched revolute joints (diagonals; NaN: none).
    pub pivot_median: f64,
    /// Median axis error of the matched joints (degrees; NaN: none).
    pub axis_median: f64,
    /// Median Chamfer/diag, failed jobs as +∞ (NaN: no jobs).
    pub chamfer_median: f64,
    /// Jobs whose export MuJoCo compiled.
    pub sim_compiled: usize,
    /// Jobs whose export is sim-clean.
    pub sim_clean: usize,
    /// Jobs whose export the native check finds clean.
    pub native_clean: usize,
    /// Jobs the native check finds clean on each whole mesh's hull instead.
    pub hulls_clean: usize,
    /// Median job seconds.
    pub seconds_median: f64,
    /// Mean job seconds.
    pub seconds_mean: f64,
}

impl Summary {
    /// `k / n` as a share (NaN when n = 0).
    pub fn share(k: usize, n: usize) -> f64 {
        if n == 0 {
            f64::NAN
        } else {
            k as f64 / n as f64
        }
    }
}

/// Median of all values, infinities included (NaN ignored; NaN when nothing is left).
pub fn median_with_inf(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        let (a, b) = (v[n / 2 - 1], v[n / 2]);
        if a.is_infinite() || b.is_infinite() {
            b
        } else {
            0.5 * (a + b)
        }
    }
}

/// The figures of `jobs` (each with its scan, for the GT joint counts of failed jobs).
pub fn summarise<'a>(jobs: impl IntoIterator<Item = (&'a ScanResult, &'a JobResult)>) -> Summary {
    let mut s = Summary::default();
    let (mut chamfer, mut pivots, mut axes, mut seconds) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (scan, job) in jobs {
        s.jobs += 1;
        s.gt_joints += scan.gt_joints;
        s.gt_revolute += scan.gt_revolute;
        seconds.push(job.seconds);
        let Some(m) = job.metrics.as_ref().filter(|_| job.error.is_none()) else {
            s.failed += 1;
            chamfer.push(f64::INFINITY);
            continue;
        };
        s.parts_exact += usize::from(m.parts_exact());
        s.types_exact += usize::from(m.types_exact());
        for j in &m.joints {
            s.axis_ok += usize::from(j.axis_ok());
            axes.extend(j.axis_deg);
            if j.kind == JointKind::Revolute {
                s.revolute_matched += usize::from(j.matched.is_some());
                s.pivot_ok += usize::from(j.pivot_ok());
                pivots.extend(j.pivot);
            }
        }
        chamfer.push(if m.chamfer_diag.is_finite() {
            m.chamfer_diag
        } else {
            f64::INFINITY
        });
        if let Some(sim) = &job.sim {
            s.sim_compiled += usize::from(sim.compiled);
            s.sim_clean += usize::from(sim.clean);
        }
        if let Some(n) = &job.native {
            s.native_clean += usize::from(n.clean);
            s.hulls_clean += usize::from(n.hulls_clean);
        }
    }
    s.chamfer_median = median_with_inf(&chamfer);
    s.pivot_median = median_with_inf(&pivots);
    s.axis_median = median_with_inf(&axes);
    s.seconds_median = median_with_inf(&seconds);
    s.seconds_mean = if seconds.is_empty() {
        f64::NAN
    } else {
        seconds.iter().sum::<f64>() / seconds.len() as f64
    };
    s
}

/// The rows of a run: for each category block, prior, guided and best-of-`samples` (the last
/// only when `samples` > 1), filtered by `keep` (row kind keys; empty: all).
pub fn row_specs(category_aware: &[bool], samples: usize, keep: &[String]) -> Vec<RowSpec> {
    let mut kinds = vec![RowKind::Prior, RowKind::Guided];
    if samples > 1 {
        kinds.push(RowKind::BestOf(samples));
    }
    category_aware
        .iter()
        .flat_map(|&aware| {
            kinds.iter().map(move |&kind| RowSpec {
                kind,
                category_aware: aware,
            })
        })
        .filter(|r| {
            keep.is_empty()
                || keep.iter().any(|k| {
                    *k == r.kind.key() || (k == "best" && matches!(r.kind, RowKind::BestOf(_)))
                })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(row: RowKind, metrics: Option<ObjectMetrics>, clean: bool) -> JobResult {
        JobResult {
            row: RowSpec {
                kind: row,
                category_aware: true,
            },
            samples: row.samples(),
            best: metrics.as_ref().map(|_| (0, 0)),
            d_pc: 0.01,
            error: metrics.is_none().then(|| "diverged".to_string()),
            metrics,
            sim: Some(SimResult {
                compiled: true,
                clean,
                rest_depth: Some(0.0),
                sweep_depth: Some(0.0),
                worst_bodies: Vec::new(),
                error: None,
            }),
            native: None,
            seconds: 2.0,
        }
    }

    #[test]
    fn failed_jobs_are_misses_in_every_share_and_infinite_in_the_chamfer_median() {
        let m = ObjectMetrics {
            parts: 2,
            gt_parts: 2,
            types: vec!["revolute"],
            gt_types: vec!["revolute"],
            joints: vec![JointMatch {
                gt_joint: 0,
                kind: JointKind::Revolute,
                matched: Some(0),
                axis_deg: Some(3.0),
                pivot: Some(0.01),
            }],
            chamfer_diag: 0.05,
        };
        let scan = |id: &str, jobs| ScanResult {
            scan: id.into(),
            object: "o".into(),
            category: Some("StorageFurniture".into()),
            view: 0,
            camera: None,
            points: 1000,
            gt_joints: 1,
            gt_revolute: 1,
            frame_error: None,
            jobs,
        };
        let a = scan("a", vec![job(RowKind::Guided, Some(m.clone()), true)]);
        let b = scan("b", vec![job(RowKind::Guided, None, false)]);
        let c = scan("c", vec![job(RowKind::Guided, Some(m), false)]);
        let all = [&a, &b, &c];
        let s = summarise(all.iter().map(|s| (*s, &s.jobs[0])));
        assert_eq!((s.jobs, s.failed), (3, 1));
        assert_eq!((s.parts_exact, s.types_exact), (2, 2));
        assert_eq!((s.gt_joints, s.axis_ok), (3, 2));
        assert_eq!((s.gt_revolute, s.revolute_matched, s.pivot_ok), (3, 2, 2));
        assert_eq!(s.sim_clean, 1);
        // 0.05, 0.05, +inf.
        assert_eq!(s.chamfer_median, 0.05);
        let s2 = summarise([(&b, &b.jobs[0])]);
        assert_eq!(s2.chamfer_median, f64::INFINITY);
    }

    #[test]
    fn rows_and_the_best_sample() {
        let rows = row_specs(&[true], 4, &[]);
        let keys: Vec<String> = rows.iter().map(|r| r.key()).collect();
        assert_eq!(
            keys,
            ["prior+category", "guided+category", "best-of-4+category"]
        );
        assert_eq!(row_specs(&[false, true], 1, &[]).len(), 4);
        assert_eq!(row_specs(&[false], 4, &["best".into()]).len(), 1);
        let failed = |index: usize| JobSample {
            index,
            seed: index as u64,
            d_pc: f64::NAN,
            score: f64::NAN,
            seconds: 1.0,
            outcome: Err(EngineError::Diverged {
                step: 1,
                t: 999,
                what: "x",
            }),
        };
        // No sample produced an object: no best.
        assert_eq!(best_of(&[failed(0), failed(1)], 2), None);
    }
}
