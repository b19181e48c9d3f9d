//! The native physics check of an export: does it move without its parts jamming?
//!
//! Why it exists: a URDF that loads but whose drawer sits inside its cabinet is no simulation
//! model. This is real-scans.md §3's *sim-clean*, computed without a simulator on the collision
//! pieces export writes ([`crate::export::collision`]): at rest (every joint at 0) no contact
//! between two parts is deeper than [`SimOptions::depth`], and none is while each movable joint
//! is swept over [`SimOptions::states`] evenly spaced states of its range (the others at 0). Every
//! pair of parts counts, parent and child included (a drawer inside its cabinet is exactly the
//! failure this is for); pieces of one part never collide with each other. Depths are GJK/EPA
//! penetration depths between convex pieces, what MuJoCo's convex collider reports; the CI test
//! `tests/sim_engine.rs` checks the verdicts against MuJoCo itself.

use crate::error::{CoreError, CoreResult};
use crate::mesh::TriMesh;
use crate::mesh::convex::{Convex, penetration};
use crate::object::{ArticulatedObject, JointKind, JointState};
use nalgebra::{Isometry3, Point3};

/// Deepest contact allowed by default (metres; real-scans.md §3).
pub const DEFAULT_DEPTH: f64 = 0.005;
/// States per joint sweep by default (real-scans.md §3).
pub const DEFAULT_STATES: usize = 5;
/// Most states per sweep accepted.
pub const MAX_STATES: usize = 101;

/// Knobs of the check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimOptions {
    /// Deepest contact (metres) a clean object may have.
    pub depth: f64,
    /// Evenly spaced states per joint sweep, both limits included (1 = the lower limit only).
    pub states: usize,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            depth: DEFAULT_DEPTH,
            states: DEFAULT_STATES,
        }
    }
}

impl SimOptions {
    /// Check the knobs.
    pub fn validate(&self) -> CoreResult<()> {
        if !(self.depth >= 0.0 && self.depth.is_finite()) {
            return Err(CoreError::invalid("sim.depth", ">= 0 metres", self.depth));
        }
        if !(1..=MAX_STATES).contains(&self.states) {
            return Err(CoreError::invalid(
                "sim.states",
                format!("1..={MAX_STATES}"),
                self.states,
            ));
        }
        Ok(())
    }
}

/// Where the deepest contact was.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorstContact {
    /// Penetration depth (metres).
    pub depth: f64,
    /// The two parts (indices into the object's parts, lower first).
    pub pair: [usize; 2],
    /// The joint being swept (index into the object's joints), `None` at rest.
    pub joint: Option<usize>,
    /// Fraction of that joint's range (0 = lower limit, 1 = upper), `None` at rest.
    pub fraction: Option<f64>,
}

/// The verdict of [`check`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimReport {
    /// No contact deeper than the limit at rest or along any sweep.
    pub clean: bool,
    /// Deepest contact at rest (metres).
    pub rest_depth: f64,
    /// Deepest contact over all sweeps (metres).
    pub sweep_depth: f64,
    /// The deepest contact overall, if any two parts touch.
    pub worst: Option<WorstContact>,
    /// The options it was checked with.
    pub options: SimOptions,
}

impl SimReport {
    /// max(rest, sweep) depth.
    pub fn worst_depth(&self) -> f64 {
        self.rest_depth.max(self.sweep_depth)
    }
}

struct Body {
    pieces: Vec<(Convex, Point3<f64>, f64)>,
}

/// The deepest contact between any two parts at the part poses `motions` (from rest).
fn deepest(bodies: &[Body], motions: &[Isometry3<f64>]) -> (f64, Option<[usize; 2]>) {
    let mut best = (0.0, None);
    for a in 0..bodies.len() {
        for b in a + 1..bodies.len() {
            for (pa, ca, ra) in &bodies[a].pieces {
                let wa = motions[a] * ca;
                for (pb, cb, rb) in &bodies[b].pieces {
                    // Bounding spheres first: most piece pairs are far apart.
                    if (motions[b] * cb - wa).norm() > ra + rb {
                        continue;
                    }
                    let d = penetration(pa, &motions[a], pb, &motions[b]);
                    if d > best.0 {
                        best = (d, Some([a, b]));
                    }
                }
            }
        }
    }
    best
}

/// Check `obj` with its collision pieces (`pieces[p]` are part p's, object frame at rest).
pub fn check(
    obj: &ArticulatedObject,
    pieces: &[Vec<TriMesh>],
    opts: &SimOptions,
) -> CoreResult<SimReport> {
    opts.validate()?;
    if pieces.len() != obj.parts.len() {
        return Err(CoreError::invalid(
            "pieces",
            format!("one list per part ({})", obj.parts.len()),
            pieces.len(),
        ));
    }
    let bodies: Vec<Body> = pieces
        .iter()
        .map(|ps| Body {
            pieces: ps
                .iter()
                .filter_map(|m| {
                    let c = Convex::new(m)?;
                    let (lo, hi) = c.bounds();
                    let mid = Point3::new(
                        0.5 * (lo[0] + hi[0]) as f64,
                        0.5 * (lo[1] + hi[1]) as f64,
                        0.5 * (lo[2] + hi[2]) as f64,
                    );
                    let r = m
                        .positions
                        .iter()
                        .map(|p| (Point3::new(p[0] as f64, p[1] as f64, p[2] as f64) - mid).norm())
                        .fold(0.0, f64::max);
                    Some((c, mid, r + 1e-6))
                })
                .collect(),
        })
        .collect();
    let rest = vec![JointState::default(); obj.joints.len()];
    let (rest_depth, rest_pair) = deepest(&bodies, &obj.part_motions(&rest));
    let mut worst = rest_pair.map(|pair| WorstContact {
        depth: rest_depth,
        pair,
        joint: None,
        fraction: None,
    });
    let mut sweep_depth: f64 = 0.0;
    for (k, j) in obj.joints.iter().enumerate() {
        if j.kind == JointKind::Fixed {
            continue;
        }
        for s in 0..opts.states {
            let f = if opts.states > 1 {
                s as f64 / (opts.states - 1) as f64
            } else {
                0.0
            };
            let mut states = rest.clone();
            states[k] = j.state_at(f);
            let (d, pair) = deepest(&bodies, &obj.part_motions(&states));
            sweep_depth = sweep_depth.max(d);
            if let Some(pair) = pair
                && worst.as_ref().is_none_or(|w| d > w.depth)
            {
                worst = Some(WorstContact {
                    depth: d,
                    pair,
                    joint: Some(k),
                    fraction: Some(f),
                });
            }
        }
    }
    Ok(SimReport {
        clean: rest_depth <= opts.depth && sweep_depth <= opts.depth,
        rest_depth,
        sweep_depth,
        worst,
        options: *opts,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::collision::{CollisionOptions, pieces};
    use crate::fixtures;
    use crate::mesh::{MeshingOptions, mesh_parts};

    #[test]
    fn the_example_objects_are_clean_on_their_exact_pieces() {
        for obj in [fixtures::cabinet(), fixtures::eight_part()] {
            let meshes = mesh_parts(&obj, None, &MeshingOptions::default()).unwrap();
            let p = pieces(&obj, &meshes, &CollisionOptions::default());
            let r = check(&obj, &p, &SimOptions::default()).unwrap();
            assert!(r.clean, "{}: {r:?}", obj.name);
            assert!(r.worst_depth() <= 0.001, "{}: {r:?}", obj.name);
        }
    }

    #[test]
    fn a_drawer_pushed_through_its_back_wall_is_not_clean() {
        let mut obj = fixtures::cabinet();
        let k = obj
            .joints
            .iter()
            .position(|j| j.kind == JointKind::Prismatic)
            .unwrap();
        // Let the drawer slide 0.3 m into the body: its back hits the body's back wall.
        let dir = obj.joints[k].axis;
        obj.joints[k].axis = -dir;
        obj.joints[k].prismatic = [0.0, 0.3];
        let meshes = mesh_parts(&obj, None, &MeshingOptions::default()).unwrap();
        let p = pieces(&obj, &meshes, &CollisionOptions::default());
        let r = check(&obj, &p, &SimOptions::default()).unwrap();
        assert!(!r.clean, "{r:?}");
        let w = r.worst.unwrap();
        assert_eq!(w.joint, Some(k));
        assert!(w.depth > 0.01, "{w:?}");
    }

    #[test]
    fn bad_options_name_the_field() {
        let e = SimOptions {
            depth: f64::NAN,
            states: 5,
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("sim.depth"), "{e}");
        let e = SimOptions {
            depth: 0.005,
            states: 0,
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("sim.states") && e.contains("1..=101"), "{e}");
    }
}
