//! The markdown of `eval real` (OUT/real.md): rows × metrics overall, then per category.
//!
//! Why it exists: one place formats the §3 figures the same way for every report, and the
//! cells say their counts ("37 % (22/60)"), so a share is never read without its population.

use super::{ScanResult, Summary, summarise};

fn pct(k: usize, n: usize) -> String {
    if n == 0 {
        "—".into()
    } else {
        format!("{:.0} % ({k}/{n})", 100.0 * k as f64 / n as f64)
    }
}

fn num(v: f64, digits: usize) -> String {
    if v.is_nan() {
        "—".into()
    } else if v.is_infinite() {
        "∞".into()
    } else {
        format!("{v:.digits$}")
    }
}

/// The table header (after a leading `what` column).
const HEADER: &str = "| jobs | failed | parts exact | joint types exact | axis ≤ 10° (of GT joints) | pivot ≤ 0.05 diag (of GT hinges; matched, median) | chamfer/diag median | sim-clean (MuJoCo; native; whole-mesh hulls, native) | seconds median (mean) |";

/// One summary as the cells after the leading column(s).
pub fn cells(s: &Summary) -> String {
    format!(
        "| {} | {} | {} | {} | {} | {} ({} matched, median {}) | {} | {} ({}; {}) | {} ({}) |",
        s.jobs,
        s.failed,
        pct(s.parts_exact, s.jobs),
        pct(s.types_exact, s.jobs),
        pct(s.axis_ok, s.gt_joints),
        pct(s.pivot_ok, s.gt_revolute),
        s.revolute_matched,
        num(s.pivot_median, 2),
        num(s.chamfer_median, 3),
        pct(s.sim_clean, s.jobs),
        pct(s.native_clean, s.jobs),
        pct(s.hulls_clean, s.jobs),
        num(s.seconds_median, 1),
        num(s.seconds_mean, 1),
    )
}

/// Row keys in the order of their first appearance.
pub fn row_keys(scans: &[ScanResult]) -> Vec<String> {
    let mut keys: Vec<String> = Vec::new();
    for s in scans {
        for j in &s.jobs {
            let k = j.row.key();
            if !keys.contains(&k) {
                keys.push(k);
            }
        }
    }
    keys
}

/// The summary of row `key` over the scans that `keep` selects.
pub fn row_summary(scans: &[ScanResult], key: &str, keep: &dyn Fn(&ScanResult) -> bool) -> Summary {
    summarise(scans.iter().filter(|s| keep(s)).flat_map(|s| {
        s.jobs
            .iter()
            .filter(|j| j.row.key() == key)
            .map(move |j| (s, j))
    }))
}

/// Sorted categories of the scans (`—` for scans without one).
pub fn categories(scans: &[ScanResult]) -> Vec<String> {
    let mut c: Vec<String> = scans
        .iter()
        .map(|s| s.category.clone().unwrap_or_else(|| "—".into()))
        .collect();
    c.sort();
    c.dedup();
    c
}

/// OUT/real.md: a title line, the overall table (rows × metrics) and the per-category table.
pub fn markdown(title: &str, scans: &[ScanResult]) -> String {
    let mut md = format!("# {title}\n\n");
    let objects = {
        let mut o: Vec<&str> = scans.iter().map(|s| s.object.as_str()).collect();
        o.sort_unstable();
        o.dedup();
        o.len()
    };
    md += &format!(
        "{} scans of {} objects; failed jobs count as misses in every share and as ∞ in the Chamfer median.\n\n",
        scans.len(),
        objects
    );
    let errors: Vec<_> = scans.iter().filter_map(|s| s.frame_error).collect();
    if !errors.is_empty() {
        let ok = errors.iter().filter(|e| e.yaw_deg <= 10.0).count();
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        md += &format!(
            "Scans moved into a user's frame (`--frame auto`): yaw within 10° on {}, median yaw error {:.1}°, median floor error {:.3} m; {} scans refused by the estimate.\n\n",
            pct(ok, errors.len()),
            median(errors.iter().map(|e| e.yaw_deg).collect()),
            median(errors.iter().map(|e| e.floor_m).collect()),
            scans.len() - errors.len(),
        );
    }
    let keys = row_keys(scans);
    md += &format!("| row {HEADER}\n|---|---|---|---|---|---|---|---|---|---|\n");
    for k in &keys {
        md += &format!("| {k} {}\n", cells(&row_summary(scans, k, &|_| true)));
    }
    md += &format!(
        "\n## Per category\n\n| row | category {HEADER}\n|---|---|---|---|---|---|---|---|---|---|---|\n"
    );
    for k in &keys {
        for c in categories(scans) {
            let s = row_summary(scans, k, &|s: &ScanResult| {
                s.category.as_deref().unwrap_or("—") == c
            });
            md += &format!("| {k} | {c} {}\n", cells(&s));
        }
    }
    md
}
