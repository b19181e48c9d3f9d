//! Files of `eval real`: the benchmark's scan records, the per-scan result files (which make a
//! stopped run resumable), and the JSON that scripts/sim_check.py prints.
//!
//! Why it exists: `eval::real` is serialisation-free (tests/architecture.rs); this maps its
//! types onto files and back. The scan-set layout is read by [`read_scan_set`] alone, so a
//! change of the benchmark's layout is one function.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::eval::real::{
    JobResult, JointMatch, NativeSim, ObjectMetrics, RowKind, RowSpec, ScanResult, SimResult,
};
use crate::object::JointKind;

/// Errors of these files.
#[derive(Debug, thiserror::Error)]
pub enum RealFileError {
    /// Reading or writing failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A file is not what it should be.
    #[error("{path}: {detail}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// The MuJoCo check could not run (not started, mujoco missing, crashed).
    #[error("sim check ({command}): {detail}")]
    SimCheck {
        /// The command line.
        command: String,
        /// What happened, with the script's stderr.
        detail: String,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> RealFileError + '_ {
    move |source| RealFileError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn malformed(path: &Path, detail: impl Into<String>) -> RealFileError {
    RealFileError::Malformed {
        path: path.to_path_buf(),
        detail: detail.into(),
    }
}

fn read_json(path: &Path) -> Result<Value, RealFileError> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    serde_json::from_str(&text).map_err(|e| malformed(path, format!("invalid JSON: {e}")))
}

/// One scan of the benchmark set.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanRecord {
    /// Scan id (unique in the set; the result file's name).
    pub id: String,
    /// The scanned object's id in the imported dataset (`DATA/objects/<object>`).
    pub object: String,
    /// Its category.
    pub category: Option<String>,
    /// View index among the object's scans.
    pub view: usize,
    /// Camera position, canonical frame.
    pub camera: Option<[f64; 3]>,
    /// The point cloud file (.ply, .npy or .json).
    pub cloud: PathBuf,
}

fn vec3(v: &Value) -> Option<[f64; 3]> {
    let a = v.as_array().filter(|a| a.len() == 3)?;
    Some([a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?])
}

/// `<object>_<view>` → (object, view).
fn split_view(stem: &str) -> Option<(String, usize)> {
    let (obj, v) = stem.rsplit_once('_')?;
    Some((obj.to_string(), v.parse().ok()?))
}

fn record(
    dir: &Path,
    v: &Value,
    fallback_cloud: Option<PathBuf>,
    path: &Path,
) -> Result<ScanRecord, RealFileError> {
    let cloud = ["cloud", "points", "file", "ply"]
        .iter()
        .find_map(|k| v[*k].as_str())
        .map(|f| dir.join(f))
        .or(fallback_cloud)
        .ok_or_else(|| malformed(path, "a scan record without a \"cloud\" file"))?;
    let stem = cloud
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let parsed = split_view(&stem);
    let object = v["object"]
        .as_str()
        .or_else(|| v["id"].as_str().filter(|_| v["object"].is_null()))
        .map(String::from)
        .or_else(|| parsed.as_ref().map(|p| p.0.clone()))
        .ok_or_else(|| malformed(path, "a scan record without an \"object\""))?;
    // The view: `view`, or an integer `scan` (real-assets.sh's testset.json), or the cloud's
    // `<object>_<view>` stem.
    let explicit = v["view"].as_u64().or_else(|| v["scan"].as_u64());
    let from_stem = parsed.as_ref().filter(|p| p.0 == object).map(|p| p.1);
    let view = explicit.map(|x| x as usize).or(from_stem).unwrap_or(0);
    let id = match v["scan"].as_str() {
        Some(id) => id.to_string(),
        None if explicit.is_some() || from_stem.is_some() => format!("{object}_{view}"),
        None => object.clone(),
    };
    Ok(ScanRecord {
        id,
        object,
        category: v["category"].as_str().map(String::from),
        view,
        camera: vec3(&v["camera"]).or_else(|| vec3(&v["eye"])),
        cloud,
    })
}

/// The scans of a benchmark set folder, sorted by (object, view). Layouts, first match wins:
///
/// 1. an index `scans.json` or `testset.json` (`physnap data testset`'s) whose `scans` or
///    `clouds` array lists records;
/// 2. one `<object>_<view>.json` record per scan next to its `<object>_<view>.ply`.
///
/// A record holds `object` (or testset's `id`), `category`, `camera: [x, y, z]` (or testset's
/// `eye`), `cloud` (file name in the folder; default: the record's own stem + `.ply`), and
/// optionally `view` (or an integer `scan`, as scripts/real-assets.sh writes it). The scan id
/// is a string `scan`, else `<object>_<view>` when the view is known (given, or the cloud's
/// `<object>_<view>` stem), else the object id.
pub fn read_scan_set(dir: &Path) -> Result<Vec<ScanRecord>, RealFileError> {
    let mut out = Vec::new();
    let index = ["scans.json", "testset.json"]
        .iter()
        .map(|f| dir.join(f))
        .find(|p| p.is_file());
    if let Some(path) = index {
        let doc = read_json(&path)?;
        let list = doc["scans"]
            .as_array()
            .or_else(|| doc["clouds"].as_array())
            .or_else(|| doc.as_array())
            .ok_or_else(|| malformed(&path, "no \"scans\" (or \"clouds\") array"))?;
        for v in list {
            out.push(record(dir, v, None, &path)?);
        }
    } else {
        let entries = std::fs::read_dir(dir).map_err(io(dir))?;
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "json"))
            .collect();
        files.sort();
        for path in files {
            let v = read_json(&path)?;
            if !v.is_object() {
                continue;
            }
            let ply = path.with_extension("ply");
            out.push(record(dir, &v, ply.is_file().then_some(ply), &path)?);
        }
    }
    // Views counted per object where records give none and ids repeat.
    out.sort_by(|a, b| (&a.object, a.view, &a.id).cmp(&(&b.object, b.view, &b.id)));
    let mut seen = std::collections::HashSet::new();
    for r in &out {
        if !seen.insert(r.id.clone()) {
            return Err(malformed(dir, format!("scan id {:?} appears twice", r.id)));
        }
    }
    Ok(out)
}

fn num(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

fn opt_num(v: Option<f64>) -> Value {
    v.map_or(Value::Null, num)
}

fn kind_of(s: &str) -> Option<JointKind> {
    match s {
        "revolute" => Some(JointKind::Revolute),
        "prismatic" => Some(JointKind::Prismatic),
        "screw" => Some(JointKind::Screw),
        "fixed" => Some(JointKind::Fixed),
        _ => None,
    }
}

/// A job as JSON (the per-scan file's `jobs` entries; also the report's).
pub fn job_json(j: &JobResult) -> Value {
    let metrics = j.metrics.as_ref().map(|m| {
        json!({
            "parts": m.parts, "gt_parts": m.gt_parts, "parts_exact": m.parts_exact(),
            "joint_types": m.types, "gt_joint_types": m.gt_types, "joint_types_exact": m.types_exact(),
            "joints": m.joints.iter().map(|g| json!({
                "gt_joint": g.gt_joint, "kind": g.kind.as_str(), "matched": g.matched,
                "axis_deg": opt_num(g.axis_deg), "axis_ok": g.axis_ok(),
                "pivot": opt_num(g.pivot), "pivot_ok": g.pivot_ok(),
            })).collect::<Vec<_>>(),
            "chamfer_diag": num(m.chamfer_diag),
        })
    });
    let sim = j.sim.as_ref().map(|s| {
        json!({
            "compiled": s.compiled, "clean": s.clean, "rest_depth": opt_num(s.rest_depth),
            "sweep_depth": opt_num(s.sweep_depth), "worst_bodies": s.worst_bodies, "error": s.error,
        })
    });
    let native = j.native.as_ref().map(|n| {
        json!({
            "clean": n.clean, "worst_depth": num(n.worst_depth),
            "hulls_clean": n.hulls_clean, "hulls_worst_depth": num(n.hulls_worst_depth),
        })
    });
    json!({
        "row": j.row.key(), "kind": j.row.kind.key(), "category_aware": j.row.category_aware,
        "samples": j.samples, "best_sample": j.best.map(|b| b.0), "best_seed": j.best.map(|b| b.1),
        "d_pc": num(j.d_pc), "failed": j.error.is_some(), "error": j.error,
        "metrics": metrics, "sim": sim, "native": native, "seconds": j.seconds,
    })
}

/// A scan's jobs as JSON (its result file).
pub fn scan_json(s: &ScanResult) -> Value {
    json!({
        "format": "physnap.eval_real_scan/v1",
        "scan": s.scan, "object": s.object, "category": s.category, "view": s.view,
        "camera": s.camera, "points": s.points, "gt_joints": s.gt_joints,
        "gt_revolute": s.gt_revolute,
        "frame_error": s.frame_error.map(|e| json!({
            "yaw_deg": e.yaw_deg, "floor_m": e.floor_m, "offset_m": e.offset_m,
        })),
        "jobs": s.jobs.iter().map(job_json).collect::<Vec<_>>(),
    })
}

fn row_of(key: &str, aware: bool) -> Option<RowSpec> {
    let kind = match key {
        "prior" => RowKind::Prior,
        "guided" => RowKind::Guided,
        k => RowKind::BestOf(k.strip_prefix("best-of-")?.parse().ok()?),
    };
    Some(RowSpec {
        kind,
        category_aware: aware,
    })
}

fn job_from(v: &Value) -> Option<JobResult> {
    let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let metrics = match &v["metrics"] {
        Value::Null => None,
        m => {
            let types = |v: &Value| -> Option<Vec<&'static str>> {
                v.as_array()?
                    .iter()
                    .map(|t| t.as_str().and_then(kind_of).map(JointKind::as_str))
                    .collect()
            };
            let joints = m["joints"]
                .as_array()?
                .iter()
                .map(|g| {
                    Some(JointMatch {
                        gt_joint: g["gt_joint"].as_u64()? as usize,
                        kind: kind_of(g["kind"].as_str()?)?,
                        matched: g["matched"].as_u64().map(|x| x as usize),
                        axis_deg: g["axis_deg"].as_f64(),
                        pivot: g["pivot"].as_f64(),
                    })
                })
                .collect::<Option<Vec<_>>>()?;
            Some(ObjectMetrics {
                parts: m["parts"].as_u64()? as usize,
                gt_parts: m["gt_parts"].as_u64()? as usize,
                types: types(&m["joint_types"])?,
                gt_types: types(&m["gt_joint_types"])?,
                joints,
                chamfer_diag: f(&m["chamfer_diag"]),
            })
        }
    };
    let sim = match &v["sim"] {
        Value::Null => None,
        s => Some(SimResult {
            compiled: s["compiled"].as_bool()?,
            clean: s["clean"].as_bool()?,
            rest_depth: s["rest_depth"].as_f64(),
            sweep_depth: s["sweep_depth"].as_f64(),
            worst_bodies: strings(&s["worst_bodies"]),
            error: s["error"].as_str().map(String::from),
        }),
    };
    let native = match &v["native"] {
        Value::Null => None,
        n => Some(NativeSim {
            clean: n["clean"].as_bool()?,
            worst_depth: f(&n["worst_depth"]),
            hulls_clean: n["hulls_clean"].as_bool()?,
            hulls_worst_depth: f(&n["hulls_worst_depth"]),
        }),
    };
    Some(JobResult {
        row: row_of(v["kind"].as_str()?, v["category_aware"].as_bool()?)?,
        samples: v["samples"].as_u64()? as usize,
        best: match (v["best_sample"].as_u64(), v["best_seed"].as_u64()) {
            (Some(i), Some(s)) => Some((i as usize, s)),
            _ => None,
        },
        d_pc: f(&v["d_pc"]),
        error: v["error"].as_str().map(String::from),
        metrics,
        sim,
        native,
        seconds: f(&v["seconds"]),
    })
}

/// Read a scan's result file back (for resuming).
pub fn read_scan_result(path: &Path) -> Result<ScanResult, RealFileError> {
    let v = read_json(path)?;
    let bad = || malformed(path, "not a physnap.eval_real_scan/v1 file");
    if v["format"].as_str() != Some("physnap.eval_real_scan/v1") {
        return Err(bad());
    }
    let jobs = v["jobs"]
        .as_array()
        .ok_or_else(bad)?
        .iter()
        .map(job_from)
        .collect::<Option<Vec<_>>>()
        .ok_or_else(bad)?;
    Ok(ScanResult {
        scan: v["scan"].as_str().ok_or_else(bad)?.to_string(),
        object: v["object"].as_str().ok_or_else(bad)?.to_string(),
        category: v["category"].as_str().map(String::from),
        view: v["view"].as_u64().unwrap_or(0) as usize,
        camera: vec3(&v["camera"]),
        points: v["points"].as_u64().unwrap_or(0) as usize,
        gt_joints: v["gt_joints"].as_u64().ok_or_else(bad)? as usize,
        gt_revolute: v["gt_revolute"].as_u64().ok_or_else(bad)? as usize,
        frame_error: match (
            v["frame_error"]["yaw_deg"].as_f64(),
            v["frame_error"]["floor_m"].as_f64(),
        ) {
            (Some(yaw_deg), Some(floor_m)) => Some(crate::eval::real::frame::FrameError {
                yaw_deg,
                floor_m,
                offset_m: v["frame_error"]["offset_m"].as_f64().unwrap_or(f64::NAN),
            }),
            _ => None,
        },
        jobs,
    })
}

/// Write `value` as pretty JSON, atomically (a stopped run leaves no half file).
pub fn write_json(path: &Path, value: &Value) -> Result<(), RealFileError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| malformed(path, e.to_string()))?;
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text + "\n").map_err(io(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io(path))
}

/// Run `python script URDF...` and read its verdicts (one per URDF, in order). Exit status 3
/// (the script's "mujoco is not importable") and any other failure are errors naming the fix.
pub fn sim_check(
    python: &Path,
    script: &Path,
    urdfs: &[PathBuf],
) -> Result<Vec<SimResult>, RealFileError> {
    if urdfs.is_empty() {
        return Ok(Vec::new());
    }
    let command = format!(
        "{} {} <{} URDF>",
        python.display(),
        script.display(),
        urdfs.len()
    );
    let err = |detail: String| RealFileError::SimCheck {
        command: command.clone(),
        detail,
    };
    let out = std::process::Command::new(python)
        .arg(script)
        .args(urdfs)
        .output()
        .map_err(|e| {
            err(format!(
                "cannot start {}: {e} (set --python / PHYSNAP_PYTHON to a Python 3 with `pip install mujoco==4.0.0`)",
                python.display()
            ))
        })?;
    let stderr = String::from_utf8_lossy(&out.stderr).trim().to_string();
    if !out.status.success() {
        return Err(err(format!("exit status {}: {stderr}", out.status)));
    }
    let doc: Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| err(format!("its output is not JSON ({e}); stderr: {stderr}")))?;
    let results = doc["results"]
        .as_array()
        .filter(|r| r.len() == urdfs.len())
        .ok_or_else(|| err("its output has no result per URDF".into()))?;
    Ok(results
        .iter()
        .map(|r| SimResult {
            compiled: r["compiled"].as_bool().unwrap_or(false),
            clean: r["clean"].as_bool().unwrap_or(false),
            rest_depth: r["rest_depth"].as_f64(),
            sweep_depth: r["sweep_depth"].as_f64(),
            worst_bodies: strings(&r["worst"]["bodies"]),
            error: r["error"].as_str().map(String::from),
        })
        .collect())
}

/// Check that `python` can import mujoco (`script --probe`), before a long run starts.
pub fn sim_probe(python: &Path, script: &Path) -> Result<String, RealFileError> {
    let command = format!("{} {} --probe", python.display(), script.display());
    let err = |detail: String| RealFileError::SimCheck {
        command: command.clone(),
        detail,
    };
    let out = std::process::Command::new(python)
        .arg(script)
        .arg("--probe")
        .output()
        .map_err(|e| {
            err(format!(
                "cannot start {}: {e} (set --python / PHYSNAP_PYTHON to a Python 3 with `pip install mujoco==4.0.0`)",
                python.display()
            ))
        })?;
    if !out.status.success() {
        return Err(err(String::from_utf8_lossy(&out.stderr).trim().to_string()));
    }
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// The strings of a JSON array (none when it is not one).
fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .map(|a| {
            a.iter()
                .filter_map(|x| x.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scan_sets_in_both_layouts() {
        let dir = std::env::temp_dir().join(format!("physnap-real-scans-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("a")).unwrap();
        std::fs::create_dir_all(dir.join("b")).unwrap();
        // Per-scan records.
        for (obj, view) in [("fridge", 1), ("fridge", 0), ("box", 0)] {
            let stem = format!("{obj}_{view}");
            std::fs::write(dir.join("a").join(format!("{stem}.ply")), "").unwrap();
            std::fs::write(
                dir.join("a").join(format!("{stem}.json")),
                format!(r#"{{"object": "{obj}", "category": "Box", "camera": [1, 2, 3]}}"#),
            )
            .unwrap();
        }
        let s = read_scan_set(&dir.join("a")).unwrap();
        let ids: Vec<&str> = s.iter().map(|r| r.id.as_str()).collect();
        assert_eq!(ids, ["box_0", "fridge_0", "fridge_1"]);
        assert_eq!(s[2].view, 1);
        assert_eq!(s[2].camera, Some([1.0, 2.0, 3.0]));
        assert_eq!(s[2].cloud, dir.join("a/fridge_1.ply"));
        // data testset's index.
        std::fs::write(
            dir.join("b/testset.json"),
            r#"{"clouds": [{"id": "obj_7", "category": "Oven", "cloud": "obj_7.ply", "eye": [0, 0, 2]}]}"#,
        )
        .unwrap();
        let s = read_scan_set(&dir.join("b")).unwrap();
        assert_eq!(s.len(), 1);
        assert_eq!((s[0].object.as_str(), s[0].view), ("obj_7", 0));
        assert_eq!(
            (s[0].id.as_str(), s[0].camera),
            ("obj_7", Some([0.0, 0.0, 2.0]))
        );
        // scripts/real-assets.sh's index: three views of one object, `scan` the view.
        std::fs::create_dir_all(dir.join("c")).unwrap();
        std::fs::write(
            dir.join("c/testset.json"),
            r#"{"clouds": [
              {"id": "prpl_fridge", "category": "Refrigerator", "scan": 2, "cloud": "prpl_fridge_2.ply", "eye": [1, 1, 1]},
              {"id": "prpl_fridge", "category": "Refrigerator", "scan": 0, "cloud": "prpl_fridge_0.ply", "eye": [1, 1, 1]},
              {"id": "prpl_fridge", "category": "Refrigerator", "scan": 1, "cloud": "prpl_fridge_1.ply", "eye": [1, 1, 1]}]}"#,
        )
        .unwrap();
        let s = read_scan_set(&dir.join("c")).unwrap();
        let ids: Vec<&str> = s.iter().map(|r| r.id.as_str()).collect();
        assert_eq!(ids, ["prpl_fridge_0", "prpl_fridge_1", "prpl_fridge_2"]);
        assert!(s.iter().all(|r| r.object == "prpl_fridge"));
        assert_eq!(s[1].cloud, dir.join("c/prpl_fridge_1.ply"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
