//! `physnap eval frame`: the frame estimate alone on every scan of a benchmark set, each scan
//! moved into a user's frame (`physnap::eval::real::frame`): yaw and floor errors, with and
//! without the camera, for +Z and +Y up. Seconds for the whole set; no generation.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use serde_json::json;

use physnap::engine::frame::estimate;
use physnap::eval::real::frame::{MovedUp, frame_error, move_of, moved};
use physnap::io::real::{read_scan_set, write_json};
use physnap::pointcloud::{Limits, PointCloud};

#[derive(Args, Debug)]
pub struct EvalFrameArgs {
    /// Scan folder (`<object>_<view>.json` records next to the clouds; as `eval real --scans`),
    /// or a benchmark folder holding it as DATA/scans.
    #[arg(long, env = "PHYSNAP_REAL_SCANS")]
    scans: PathBuf,
    /// Seed of the moves (as `eval real --frame auto`).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Write the per-scan errors and the summary here (JSON).
    #[arg(long, env = "PHYSNAP_OUT")]
    out: Option<PathBuf>,
}

/// Yaw errors within this many degrees count as found (the target).
const YAW_OK_DEG: f64 = 10.0;

pub fn eval_frame(a: EvalFrameArgs) -> anyhow::Result<()> {
    let dir = if a.scans.join("scans").is_dir() {
        a.scans.join("scans")
    } else {
        a.scans.clone()
    };
    let scans =
        read_scan_set(&dir).with_context(|| format!("reading scans of {}", dir.display()))?;
    if scans.is_empty() {
        bail!("no scans in {}", dir.display());
    }
    let limits = Limits {
        min_points: 1,
        max_points: physnap::engine::guidance::MAX_POINTS,
    };
    let mut rows = Vec::new();
    let mut per_scan = Vec::new();
    println!(
        "| up | camera | scans | yaw ≤ {YAW_OK_DEG}° | yaw error, median | floor error, median (m) | origin offset, median (m) | refused |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for up in [MovedUp::Z, MovedUp::Y] {
        for use_camera in [true, false] {
            let (mut ok, mut n, mut refused) = (0usize, 0usize, 0usize);
            let (mut yaws, mut floors, mut offsets) = (Vec::new(), Vec::new(), Vec::new());
            for s in &scans {
                if use_camera && s.camera.is_none() {
                    continue;
                }
                let points = PointCloud::read(&s.cloud, &limits)
                    .with_context(|| format!("reading {}", s.cloud.display()))?
                    .points;
                let m = move_of(&s.id, a.seed, up);
                let cams: Vec<[f32; 3]> = match (use_camera, s.camera) {
                    (true, Some(c)) => moved(&m, &[c.map(|v| v as f32)]),
                    _ => Vec::new(),
                };
                n += 1;
                match estimate(&moved(&m, &points), up.vector(), &cams) {
                    Ok(e) => {
                        let err = frame_error(&m, &e.frame);
                        ok += usize::from(err.yaw_deg <= YAW_OK_DEG);
                        yaws.push(err.yaw_deg);
                        floors.push(err.floor_m);
                        offsets.push(err.offset_m);
                        per_scan.push(json!({
                            "scan": s.id, "up": up.as_str(), "camera": use_camera,
                            "yaw_error_deg": err.yaw_deg, "floor_error_m": err.floor_m,
                            "offset_m": err.offset_m,
                            "chosen_by": e.source.as_str(), "plane_share": e.plane_share,
                            "camera_azimuth_deg": s.camera.map(|c| c[1].atan2(c[0]).to_degrees().rem_euclid(360.0)),
                            "frame": physnap::io::verdict::frame_json(&e),
                        }));
                    }
                    Err(err) => {
                        refused += 1;
                        per_scan.push(json!({
                            "scan": s.id, "up": up.as_str(), "camera": use_camera,
                            "error": err.to_string(),
                        }));
                    }
                }
            }
            let median = |v: &mut Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
            };
            let share = ok as f64 / n.max(1) as f64;
            let (ym, fm) = (median(&mut yaws), median(&mut floors));
            let om = median(&mut offsets);
            println!(
                "| +{} | {} | {n} | {:.0} % ({ok}) | {ym:.1}° | {fm:.4} | {om:.4} | {refused} |",
                up.as_str().to_uppercase(),
                if use_camera { "yes" } else { "no" },
                100.0 * share
            );
            rows.push(json!({
                "up": up.as_str(), "camera": use_camera, "scans": n, "yaw_ok": ok,
                "yaw_ok_share": share, "yaw_median_deg": ym, "floor_median_m": fm,
                "offset_median_m": om,
                "refused": refused,
            }));
        }
    }
    if let Some(out) = &a.out {
        write_json(
            out,
            &json!({
                "format": "physnap.eval_frame/v1",
                "scans": dir.display().to_string(),
                "seed": a.seed,
                "yaw_ok_deg": YAW_OK_DEG,
                "rows": rows,
                "per_scan": per_scan,
            }),
        )?;
        println!("report: {}", out.display());
    }
    Ok(())
}
