//! `physnap data synth`: generate N procedural objects in parallel and write them in the
//! PartNet-Mobility layout.
//!
//! Why it exists: it is the one place that turns (seed, N, categories) into a data set on disk.
//! Object i gets category `categories[i % len]` (round-robin, so every category is covered
//! evenly) and its own random stream `Rng::fork(seed, i)`, so the output is byte-identical for a
//! given seed whatever the thread count or scheduling. Every written object has passed
//! `validity::check`; rejected draws are counted per category, never written.

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;
use serde_json::json;

use super::rng::Rng;
use super::synth::generate_valid;
use super::{DataError, partnet};

/// Version of the procedural generator; bump when output for a seed changes.
pub const GENERATOR_VERSION: &str = "physnap-synth-1";

/// Options of a synth run.
#[derive(Debug, Clone)]
pub struct SynthOptions {
    /// Number of objects.
    pub objects: usize,
    /// Seed.
    pub seed: u64,
    /// Canonical category names, round-robin.
    pub categories: Vec<String>,
    /// Draws per object before giving up on it.
    pub max_attempts: usize,
}

/// Statistics of a synth run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SynthReport {
    /// Objects written.
    pub written: usize,
    /// Objects per category.
    pub per_category: BTreeMap<String, usize>,
    /// Rejected draws per category (failed validity checks).
    pub rejected: BTreeMap<String, usize>,
    /// Objects per part count (2..=8).
    pub part_histogram: BTreeMap<usize, usize>,
    /// Joints per type.
    pub joint_histogram: BTreeMap<String, usize>,
    /// Objects that could not be generated: (index, reason).
    pub failed: Vec<(usize, String)>,
}

/// One written object's statistics.
struct Written {
    category: String,
    rejected: usize,
    parts: usize,
    kinds: Vec<&'static str>,
}

/// Generate and write `opts.objects` objects into `out` (one folder per object, `000000`, …),
/// plus `synth.json` with the report.
pub fn synthesize(
    out: &Path,
    opts: &SynthOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SynthReport, DataError> {
    if opts.categories.is_empty() {
        return Err(DataError::Option(crate::error::Invalid {
            field: "categories".into(),
            limit: "at least one category".into(),
            value: "none".into(),
        }));
    }
    std::fs::create_dir_all(out).map_err(DataError::io(out))?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<Result<Written, (usize, String)>> = (0..opts.objects)
        .into_par_iter()
        .map(|i| {
            let cat = &opts.categories[i % opts.categories.len()];
            let mut rng = Rng::fork(opts.seed, i as u64);
            let r = generate_valid(cat, &mut rng, opts.max_attempts)
                .map_err(|e| (i, e.to_string()))
                .and_then(|(obj, rejected)| {
                    let id = format!("{i:06}");
                    partnet::write_object(&obj, &id, out).map_err(|e| (i, e.to_string()))?;
                    let kinds = obj.object.joints.iter().map(|j| j.kind.as_str()).collect();
                    Ok(Written {
                        category: cat.clone(),
                        rejected,
                        parts: obj.object.parts.len(),
                        kinds,
                    })
                });
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(n, opts.objects);
            r
        })
        .collect();
    let mut report = SynthReport::default();
    for r in results {
        match r {
            Ok(w) => {
                report.written += 1;
                *report.per_category.entry(w.category.clone()).or_default() += 1;
                *report.rejected.entry(w.category).or_default() += w.rejected;
                *report.part_histogram.entry(w.parts).or_default() += 1;
                for k in w.kinds {
                    *report.joint_histogram.entry(k.to_string()).or_default() += 1;
                }
            }
            Err(f) => report.failed.push(f),
        }
    }
    let summary = json!({
        "generator": GENERATOR_VERSION,
        "seed": opts.seed,
        "objects": opts.objects,
        "written": report.written,
        "categories": opts.categories,
        "per_category": report.per_category,
        "rejected_draws": report.rejected,
        "part_histogram": report.part_histogram.iter().map(|(k, v)| (k.to_string(), *v)).collect::<BTreeMap<_, _>>(),
        "joint_histogram": report.joint_histogram,
        "failed": report.failed.iter().map(|(i, r)| json!({"index": i, "reason": r})).collect::<Vec<_>>(),
    });
    let path = out.join("synth.json");
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&summary).unwrap_or_default(),
    )
    .map_err(DataError::io(&path))?;
    Ok(report)
}
