//! `physnap check-sim DIR`: is an export directory simulation-clean?
//!
//! Reads `DIR/object.json` (the kinematics) and the collision pieces the URDF names
//! (`DIR/meshes/<link>_collision_<k>.obj`, link frames), and runs the native check
//! ([`physnap::sim`]): contacts at rest and along every joint's sweep. An export without
//! collision pieces (written before they existed) is decomposed from its visual meshes
//! (`meshes/<link>.obj`), as export would now do. Prints a summary, or the JSON report with
//! `--json`; exits 0 when clean, 1 when not (or on an error).

use anyhow::{Context, bail};
use clap::Args;
use physnap::export::collision::{CollisionOptions, part_pieces};
use physnap::export::names::safe_unique;
use physnap::export::urdf::link_frames;
use physnap::mesh::{TriMesh, obj};
use physnap::object::ArticulatedObject;
use physnap::sim::{SimOptions, SimReport, check};
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub(crate) struct CheckSimArgs {
    /// An export directory (`physnap export`/`generate` output: object.json + meshes/).
    #[arg(env = "PHYSNAP_CHECK_DIR")]
    pub(crate) dir: PathBuf,

    /// Deepest contact (metres) a clean object may have.
    #[arg(long, env = "PHYSNAP_SIM_DEPTH", default_value_t = physnap::sim::DEFAULT_DEPTH)]
    pub(crate) depth: f64,

    /// Evenly spaced states per joint sweep (limits included).
    #[arg(long, env = "PHYSNAP_SIM_STATES", default_value_t = physnap::sim::DEFAULT_STATES)]
    pub(crate) states: usize,

    /// Print the report as JSON (format physnap.sim_report/v1) instead of a summary.
    #[arg(long, env = "PHYSNAP_SIM_JSON")]
    pub(crate) json: bool,
}

fn read_obj(path: &Path, frame: &nalgebra::Vector3<f64>) -> anyhow::Result<TriMesh> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mesh = obj::parse(&text).with_context(|| format!("parsing {}", path.display()))?;
    let f = frame.map(|v| v as f32);
    Ok(mesh.map_positions(|p| [p[0] + f.x, p[1] + f.y, p[2] + f.z]))
}

/// Each part's collision pieces as an export directory holds them (object frame at rest), and
/// whether they were decomposed from the visual meshes because the directory had none.
pub(crate) fn read_pieces(
    dir: &Path,
    obj: &physnap::object::ArticulatedObject,
) -> anyhow::Result<(Vec<Vec<TriMesh>>, bool)> {
    let names = safe_unique(&obj.parts.iter().map(|p| p.name.clone()).collect::<Vec<_>>());
    let frames = link_frames(obj);
    let meshes = dir.join("meshes");
    let mut pieces = Vec::with_capacity(names.len());
    for (name, frame) in names.iter().zip(&frames) {
        let mut ps = Vec::new();
        for k in 0.. {
            let path = meshes.join(format!("{name}_collision_{k}.obj"));
            if !path.exists() {
                break;
            }
            ps.push(read_obj(&path, frame)?);
        }
        pieces.push(ps);
    }
    if pieces.iter().any(|p| !p.is_empty()) {
        return Ok((pieces, false));
    }
    let opts = CollisionOptions::default();
    let mut decomposed = Vec::with_capacity(names.len());
    for ((name, frame), part) in names.iter().zip(&frames).zip(&obj.parts) {
        let path = meshes.join(format!("{name}.obj"));
        let visual = if path.exists() {
            read_obj(&path, frame)?
        } else {
            TriMesh::default()
        };
        decomposed.push(part_pieces(part, &visual, &opts));
    }
    Ok((decomposed, true))
}

/// One line: the verdict, the deepest contacts and where the worst one is.
pub(crate) fn summary(obj: &ArticulatedObject, r: &SimReport) -> String {
    let verdict = if r.clean {
        "sim-clean"
    } else {
        "NOT sim-clean"
    };
    let mut s = format!(
        "{verdict}: deepest contact {:.4} m at rest, {:.4} m along the joints (limit {} m, {} states per joint)",
        r.rest_depth, r.sweep_depth, r.options.depth, r.options.states
    );
    if let Some(w) = r.worst.as_ref().filter(|w| w.depth > 0.0) {
        let name = |p: usize| obj.parts.get(p).map_or("?", |p| p.name.as_str());
        let at = match (w.joint, w.fraction) {
            (Some(k), Some(f)) => format!(
                "with joint {} at {:.0} % of its range",
                obj.joints.get(k).map_or("?", |j| name(j.child)),
                100.0 * f
            ),
            _ => "at rest".into(),
        };
        s += &format!("; worst: {} and {} {at}", name(w.pair[0]), name(w.pair[1]));
    }
    s
}

pub(crate) fn check_sim(a: CheckSimArgs) -> anyhow::Result<()> {
    let opts = SimOptions {
        depth: a.depth,
        states: a.states,
    };
    opts.validate()?;
    let path = a.dir.join("object.json");
    let obj = physnap::io::object_json::read(&path).with_context(|| {
        format!(
            "reading {} (is {} an export directory?)",
            path.display(),
            a.dir.display()
        )
    })?;
    let (pieces, decomposed) = read_pieces(&a.dir, &obj)?;
    if decomposed {
        tracing::warn!(
            "{} has no collision pieces (meshes/<link>_collision_<k>.obj); decomposed its visual meshes",
            a.dir.display()
        );
    }
    let report = check(&obj, &pieces, &opts)?;
    let n: usize = pieces.iter().map(Vec::len).sum();
    if a.json {
        let mut doc = physnap::io::verdict::sim_json(&obj, &report);
        doc["format"] = "physnap.sim_report/v1".into();
        println!("{doc}");
    } else {
        println!(
            "{}: {} parts, {n} collision pieces; {}",
            a.dir.display(),
            obj.parts.len(),
            summary(&obj, &report)
        );
    }
    if !report.clean {
        bail!(
            "not sim-clean: a contact {:.4} m deep exceeds {} m",
            report.worst_depth(),
            opts.depth
        );
    }
    Ok(())
}
