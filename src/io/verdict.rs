//! JSON of what a generated object is judged by: the best-of-N ranking terms and the physics
//! check.
//!
//! Why it exists: `ranking.json` (CLI and service), `object.json`'s `sim` and `physnap
//! check-sim --json` all report these; one writer keeps their keys the same everywhere.

use serde_json::{Value, json};

use crate::engine::frame::FrameEstimate;
use crate::eval::rank::RankTerms;
use crate::object::ArticulatedObject;
use crate::sim::SimReport;

fn num(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

/// `{clean, worst_depth_m, pair, joint, fraction, rest_depth_m, sweep_depth_m, depth_limit_m,
/// states}`: `pair` names the two parts of the deepest contact, `joint` the swept joint (by
/// its child part; null at rest), `fraction` how far through its range.
pub fn sim_json(obj: &ArticulatedObject, r: &SimReport) -> Value {
    let name = |p: usize| obj.parts.get(p).map(|p| p.name.clone());
    let w = r.worst.as_ref();
    json!({
        "clean": r.clean,
        "worst_depth_m": num(r.worst_depth()),
        "pair": w.map(|w| [name(w.pair[0]), name(w.pair[1])]),
        "joint": w.and_then(|w| w.joint).and_then(|k| obj.joints.get(k)).and_then(|j| name(j.child)),
        "fraction": w.and_then(|w| w.fraction),
        "rest_depth_m": num(r.rest_depth),
        "sweep_depth_m": num(r.sweep_depth),
        "depth_limit_m": r.options.depth,
        "states": r.options.states,
    })
}

/// A sample's ranking terms, each in the unit the score adds it in, with its sim check.
pub fn terms_json(obj: &ArticulatedObject, t: &RankTerms) -> Value {
    let diag = t.object_diagonal;
    json!({
        "d_pc_per_scan_diagonal": num(t.d_pc / t.scan_diagonal),
        "free": num(t.free),
        "attach_per_object_diagonal": num(t.attach / diag),
        "o_mesh": num(t.o_mesh),
        "sim_depth_per_object_diagonal": num(t.sim.map_or(f64::NAN, |s| s.worst_depth() / diag)),
        "sim": t.sim.as_ref().map(|s| sim_json(obj, s)),
    })
}

/// The frame estimate of a scan in the user's frame (`ranking.json` `frame`): the transform,
/// the floor, how the yaw was chosen and every hypothesis's terms.
pub fn frame_json(e: &FrameEstimate) -> Value {
    let f = &e.frame;
    json!({
        "mode": "auto",
        "up": <[f64; 3]>::from(f.up),
        "yaw": f.yaw,
        "yaw_degrees": f.yaw.to_degrees(),
        "translation": <[f64; 3]>::from(f.translation),
        "floor": e.floor,
        "plane_share": e.plane_share,
        "chosen_by": e.source.as_str(),
        "hypotheses": e.hypotheses.iter().enumerate().map(|(k, h)| json!({
            "yaw_degrees": h.yaw.to_degrees(),
            "face_share": h.face_share,
            "relief": h.relief,
            "camera": h.camera,
            "score": h.score,
            "chosen": k == e.chosen,
        })).collect::<Vec<_>>(),
    })
}

/// One line on the estimate, for a terminal.
pub fn frame_summary(e: &FrameEstimate) -> String {
    format!(
        "frame: yaw {:.1}° (by {}), floor {:.3} m along up, translation [{:.3}, {:.3}, {:.3}]",
        e.frame.yaw.to_degrees(),
        e.source.as_str(),
        e.floor,
        e.frame.translation.x,
        e.frame.translation.y,
        e.frame.translation.z
    )
}
