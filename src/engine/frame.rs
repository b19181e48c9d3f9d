//! Finding a scan's canonical frame (real-scans.md §7): the floor, the yaw and the position of
//! a scan given in any right-handed metric frame with a known up direction.
//!
//! ```text
//! 1. U(up) turns up onto +Z (crate::frame::up_rotation)
//! 2. floor   = the lowest point along up that is not ISOLATED (below the FLOOR_QUANTILE
//!              height), less half the points' spacing (the lowest sampled row sits that far
//!              above an edge)
//! 3. normals = PCA of each point's NEIGHBOURS nearest points; the planar, near-horizontal
//!              ones are on vertical planes
//! 4. yaw₀    = the peak of their directions mod 90° (furniture is box-like), refined by the
//!              circular mean of 4φ near the peak; the planes within BOX_TOLERANCE_DEG of it
//!              (mod 90°) are the box's faces; with under MIN_PLANE_SHARE of the points on
//!              them (a view from high above sees mostly the top), yaw₀ is the smallest
//!              rectangle around the footprint instead, if it is one (MIN_RECTANGULARITY,
//!              MIN_RECTANGULARITY_WITH_CAMERA with a camera);
//!              a round object has no yaw of its own: its camera decides
//! 5. the four hypotheses k·90° − yaw₀ put one of the four box faces at the front (−X); each
//!    scores  face share (the share of vertical-plane points on that face's side of the box)
//!          + RELIEF_WEIGHT · relief share (that face's share of the faces' median depth
//!            behind the box's side: a front's doors sit in a frame under handles, a side
//!            panel is flat)
//!          + CAMERA_WEIGHT · cos(angle between the face's normal and the camera's side)
//!    (a face the camera looks at from more than 75° away is ruled out; the first two terms
//!    count in full from MIN_PLANE_SHARE of the points on the box's planes, less below)
//!    and the best one wins (ties: the lower k)
//! 6. translation: the rotated scan's box centred in x/y, the floor at z = 0
//! ```
//!
//! Why it exists: the prior generates objects in the canonical frame (+Z up, front −X, floor
//! z = 0, centred in x/y), and a depth camera's scan is in the camera's or the room's frame.
//! The face share is the scan's own evidence of its front: a view in the paper's protocol
//! (azimuth within ±60° of the front, from above) sees the front, the top and at most one
//! side, and sees the front the most. The camera, when given, says the same more directly.
//! Deterministic: the same points, up and cameras give the same frame.

use nalgebra::{Matrix3, Rotation3, SymmetricEigen, Vector3};

use super::EngineError;
use crate::error::Invalid;
use crate::frame::{ScanFrame, check_up, up_rotation};

/// Points whose normals are estimated (a stride of the cloud).
pub const MAX_NORMAL_POINTS: usize = 1500;
/// Neighbours of a point's PCA normal (itself included).
pub const NEIGHBOURS: usize = 12;
/// A normal is horizontal (its point on a vertical plane) within this many degrees.
pub const VERTICAL_TOLERANCE_DEG: f64 = 15.0;
/// A neighbourhood is planar when its smallest PCA variance is below this share of the middle.
pub const PLANARITY: f64 = 0.05;
/// Below this quantile of the heights, only points that are not isolated can be the floor.
pub const FLOOR_QUANTILE: f64 = 0.01;
/// A point is isolated when its nearest neighbour is farther than this many median spacings.
pub const ISOLATED: f64 = 3.0;
/// A scan whose height is below this share of its horizontal extent is too flat to stand.
pub const MIN_HEIGHT_SHARE: f64 = 0.02;
/// Fewest points on the dominant vertical planes (share of the normals) that decide a yaw
/// without a camera.
pub const MIN_PLANE_SHARE: f64 = 0.1;
/// A vertical plane belongs to the dominant box when its normal is within this many degrees
/// of the dominant direction (mod 90°).
pub const BOX_TOLERANCE_DEG: f64 = 10.0;
/// A hypothesis whose front faces the camera at more than 75° (cos below this) is ruled out:
/// the scanned side is the front within about ±60° (real-scans.md §2).
pub const MIN_CAMERA_COS: f64 = 0.26;
/// Weight of a face's relief share (module docs).
pub const RELIEF_WEIGHT: f64 = 1.0;
/// Below this sum of the faces' median depths (share of the box diagonal) the faces are all
/// flat and relief says nothing.
pub const MIN_RELIEF: f64 = 0.005;
/// Fewest face points that decide the front of a footprint rectangle without a camera.
pub const MIN_FACE_POINTS: usize = 10;
/// A footprint is a rectangle (it has a yaw) when its convex hull fills this share of its
/// smallest enclosing rectangle (a disc fills π/4 ≈ 0.785).
pub const MIN_RECTANGULARITY: f64 = 0.88;
/// With a camera a footprint filling this share is taken as a rectangle: the camera then picks
/// its front side, and a round object, which has no yaw of its own, loses nothing by it (a
/// stove's knobs and burners leave its footprint ≈ 0.8 full).
pub const MIN_RECTANGULARITY_WITH_CAMERA: f64 = 0.75;

/// Weight of the camera's side against the face share (module docs).
pub const CAMERA_WEIGHT: f64 = 1.0;
/// A face's points lie within this share of the box's horizontal extent of its side.
pub const FACE_BAND: f64 = 0.15;

/// How the chosen yaw hypothesis was decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum YawSource {
    /// Face shares and the camera's side.
    PlanesAndCamera,
    /// Face shares alone (no camera).
    Planes,
    /// No vertical planes: the front faces the camera.
    Camera,
}

impl YawSource {
    /// JSON name.
    pub fn as_str(self) -> &'static str {
        match self {
            YawSource::PlanesAndCamera => "planes+camera",
            YawSource::Planes => "planes",
            YawSource::Camera => "camera",
        }
    }
}

/// One yaw hypothesis and its score terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hypothesis {
    /// The frame's yaw (radians, [0, 2π)).
    pub yaw: f64,
    /// Share of the vertical-plane points on the face this hypothesis puts at the front.
    pub face_share: f64,
    /// That face's share of the faces' relief: how deep its points lie behind the box's side
    /// (doors and drawers sit inside a frame, handles stand out, a side panel is flat).
    pub relief: f64,
    /// cos of the angle between that face's normal and the camera's side (None: no camera).
    pub camera: Option<f64>,
    /// face_share + CAMERA_WEIGHT · camera.
    pub score: f64,
}

/// What [`estimate`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameEstimate {
    /// The scan → canonical transform.
    pub frame: ScanFrame,
    /// The floor's height along up, in the scan's frame (metres).
    pub floor: f64,
    /// Share of the normals that lie on vertical planes.
    pub plane_share: f64,
    /// The hypotheses in order of k (empty when the camera alone decided).
    pub hypotheses: Vec<Hypothesis>,
    /// Index of the chosen one in `hypotheses`.
    pub chosen: usize,
    /// How it was chosen.
    pub source: YawSource,
}

fn invalid(field: &str, limit: &str, value: String) -> EngineError {
    EngineError::Invalid(Invalid {
        field: field.into(),
        limit: limit.into(),
        value,
    })
}

/// The `q`-quantile of `v` (sorted in place), linear between neighbours.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let x = q * (v.len() - 1) as f64;
    let i = x.floor() as usize;
    let j = (i + 1).min(v.len() - 1);
    v[i] + (v[j] - v[i]) * (x - i as f64)
}

/// PCA normal, planarity (smallest variance ÷ middle variance) and nearest-neighbour distance
/// of each reference point.
fn normals(points: &[Vector3<f64>]) -> Vec<(Vector3<f64>, f64, f64)> {
    let k = NEIGHBOURS.min(points.len());
    let mut d2 = vec![(0.0f64, 0usize); points.len()];
    points
        .iter()
        .map(|p| {
            for (j, q) in points.iter().enumerate() {
                d2[j] = ((q - p).norm_squared(), j);
            }
            if k < d2.len() {
                d2.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
            }
            let nb = &d2[..k];
            let nearest = nb
                .iter()
                .filter(|&&(_, j)| !std::ptr::eq(&points[j], p))
                .map(|&(d, _)| d)
                .fold(f64::INFINITY, f64::min)
                .sqrt();
            let mean = nb.iter().map(|&(_, j)| points[j]).sum::<Vector3<f64>>() / k as f64;
            let mut cov = Matrix3::zeros();
            for &(_, j) in nb {
                let r = points[j] - mean;
                cov += r * r.transpose();
            }
            let eig = SymmetricEigen::new(cov);
            let mut order = [0usize, 1, 2];
            order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
            let n = eig.eigenvectors.column(order[0]).into_owned();
            let mid = eig.eigenvalues[order[1]].max(1e-30);
            (n, eig.eigenvalues[order[0]].max(0.0) / mid, nearest)
        })
        .collect()
}

/// The dominant direction mod 90° of horizontal normals, radians in (−π/4, π/4].
fn dominant_yaw(dirs: &[f64]) -> f64 {
    // Histogram of 4φ in 1° bins of the folded angle, smoothed circularly over ±3 bins.
    const BINS: usize = 90;
    let mut hist = [0.0f64; BINS];
    let bin = |phi: f64| {
        let deg = phi.to_degrees().rem_euclid(90.0);
        (deg as usize).min(BINS - 1)
    };
    for &phi in dirs {
        hist[bin(phi)] += 1.0;
    }
    let smooth = |i: usize| -> f64 {
        (-3i64..=3)
            .map(|o| hist[(i as i64 + o).rem_euclid(BINS as i64) as usize] * (4 - o.abs()) as f64)
            .sum()
    };
    let peak = (0..BINS)
        .max_by(|&a, &b| smooth(a).total_cmp(&smooth(b)).then(b.cmp(&a)))
        .unwrap_or(0);
    let centre = (peak as f64 + 0.5).to_radians();
    // Circular mean of 4φ within ±7.5° of the peak.
    let (mut s, mut c) = (0.0, 0.0);
    for &phi in dirs {
        let d = ((phi - centre) * 4.0)
            .sin()
            .atan2(((phi - centre) * 4.0).cos())
            / 4.0;
        if d.abs() <= 7.5f64.to_radians() {
            s += (4.0 * phi).sin();
            c += (4.0 * phi).cos();
        }
    }
    let yaw = if s == 0.0 && c == 0.0 {
        centre
    } else {
        s.atan2(c) / 4.0
    };
    fold_quarter(yaw)
}

/// An angle mod 90°, into (−π/4, π/4].
fn fold_quarter(a: f64) -> f64 {
    let q = std::f64::consts::FRAC_PI_2;
    let y = a.rem_euclid(q);
    if y > q / 2.0 { y - q } else { y }
}

/// The x/y box (lo, hi) of `points`; (+∞, −∞) for none.
fn xy_bounds(points: impl IntoIterator<Item = [f64; 2]>) -> ([f64; 2], [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// The yaw (mod 90°, in (−π/4, π/4]) of the smallest rectangle around the points' footprint
/// (rotating calipers over its convex hull); None when the footprint is not rectangular.
fn footprint_yaw(points: &[Vector3<f64>], min_rectangularity: f64) -> Option<f64> {
    let mut pts: Vec<[f64; 2]> = points.iter().map(|p| [p.x, p.y]).collect();
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    pts.dedup();
    if pts.len() < 3 {
        return None;
    }
    // Andrew's monotone chain.
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    if hull.len() < 3 {
        return None;
    }
    let area: f64 = (0..hull.len())
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        .abs()
        / 2.0;
    let mut best = (f64::INFINITY, 0.0);
    for i in 0..hull.len() {
        let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
        let theta = (b[1] - a[1]).atan2(b[0] - a[0]);
        let (c, s) = (theta.cos(), theta.sin());
        let (lo, hi) = xy_bounds(
            hull.iter()
                .map(|p| [c * p[0] + s * p[1], -s * p[0] + c * p[1]]),
        );
        let rect = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        if rect < best.0 {
            best = (rect, theta);
        }
    }
    if !(best.0 > 0.0 && area / best.0 >= min_rectangularity) {
        return None;
    }
    Some(fold_quarter(best.1))
}

/// Estimate the frame of `points` (scan frame, metres) with up direction `up`; `cameras` (scan
/// frame) decide the front side when given. Errors: a bad `up`, too few points, a scan too
/// flat to stand on a floor, or (without a camera) one without vertical planes; each names
/// the field and hints at `frame: canonical`.
pub fn estimate(
    points: &[[f32; 3]],
    up: [f64; 3],
    cameras: &[[f32; 3]],
) -> Result<FrameEstimate, EngineError> {
    let up = check_up("up", up).map_err(|e| match e {
        crate::CoreError::Invalid(i) => EngineError::Invalid(i),
        other => invalid("up", "a finite, non-zero vector", other.to_string()),
    })?;
    const HINT: &str =
        "use frame canonical (the scan already in physnap's frame: +Z up, front −X, floor z = 0)";
    if points.len() < NEIGHBOURS * 2 {
        return Err(invalid(
            "points",
            &format!(
                "at least {} points to find the frame; or {HINT}",
                NEIGHBOURS * 2
            ),
            points.len().to_string(),
        ));
    }
    let u = up_rotation(&up);
    let lifted: Vec<Vector3<f64>> = points
        .iter()
        .map(|p| u * Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect();
    let mut heights: Vec<f64> = lifted.iter().map(|p| p.z).collect();
    let lowest = quantile(&mut heights, FLOOR_QUANTILE);
    let top = heights[heights.len() - 1];
    let (lo, hi) = xy_bounds(lifted.iter().map(|p| [p.x, p.y]));
    let horizontal = (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
    if !(top - lowest > MIN_HEIGHT_SHARE * horizontal && top - lowest > 1e-6) {
        return Err(invalid(
            "points",
            &format!(
                "a scan at least {MIN_HEIGHT_SHARE} of its width tall along up, to find a floor and vertical planes; check up, or {HINT}"
            ),
            format!("{:.4} m tall, {:.4} m wide", top - lowest, horizontal),
        ));
    }
    // Normals of a stride of the points.
    let stride = points.len().div_ceil(MAX_NORMAL_POINTS).max(1);
    let reference: Vec<Vector3<f64>> = lifted.iter().step_by(stride).copied().collect();
    let sin_tol = VERTICAL_TOLERANCE_DEG.to_radians().sin();
    let normals = normals(&reference);
    // The lowest sampled row of a surface lies on average half a point spacing above its
    // bottom edge: the floor is that much below the lowest points.
    // (The reference points are a stride of the cloud: on a surface their spacing is √stride
    // times the cloud's.)
    let mut nn: Vec<f64> = normals
        .iter()
        .map(|n| n.2)
        .filter(|d| d.is_finite())
        .collect();
    let median_nn = if nn.is_empty() {
        0.0
    } else {
        quantile(&mut nn, 0.5)
    };
    let spacing = median_nn / (stride as f64).sqrt();
    // The lowest point that is not isolated (a stray depth pixel floats alone).
    let lowest = normals
        .iter()
        .zip(&reference)
        .filter(|(n, _)| n.2 <= ISOLATED * median_nn)
        .map(|(_, p)| p.z)
        .fold(lowest, f64::min);
    let floor = lowest - spacing / 2.0;
    let planar: Vec<(Vector3<f64>, f64)> = normals
        .into_iter()
        .zip(&reference)
        .filter(|((n, flat, _), _)| *flat < PLANARITY && n.z.abs() < sin_tol)
        .map(|((n, _, _), p)| (*p, n.y.atan2(n.x)))
        .collect();
    // The dominant direction, and the share of the points whose planes face it (mod 90°): a
    // box's faces put most planar normals there, a round object's spread them evenly. With
    // too few (a view from high above sees mostly the top), the footprint's rectangle.
    let dirs: Vec<f64> = planar.iter().map(|&(_, phi)| phi).collect();
    let on_box = |phi: f64, yaw0: f64| {
        let d = (phi - yaw0).rem_euclid(std::f64::consts::FRAC_PI_2);
        d.min(std::f64::consts::FRAC_PI_2 - d) <= BOX_TOLERANCE_DEG.to_radians()
    };
    let from_planes = (!dirs.is_empty()).then(|| dominant_yaw(&dirs));
    let share_of = |yaw0: f64| {
        dirs.iter().filter(|&&phi| on_box(phi, yaw0)).count() as f64 / reference.len() as f64
    };
    let (yaw0, by_planes) = match from_planes.filter(|&y| share_of(y) >= MIN_PLANE_SHARE) {
        Some(y) => (Some(y), true),
        None => {
            let min = if cameras.is_empty() {
                MIN_RECTANGULARITY
            } else {
                MIN_RECTANGULARITY_WITH_CAMERA
            };
            (footprint_yaw(&lifted, min), false)
        }
    };
    let planar: Vec<(Vector3<f64>, f64)> = match yaw0 {
        Some(y) => planar
            .into_iter()
            .filter(|&(_, phi)| on_box(phi, y))
            .collect(),
        None => Vec::new(),
    };
    let plane_share = planar.len() as f64 / reference.len() as f64;
    // The camera's side: its horizontal direction from the scan's box centre.
    let centre = Vector3::new((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, 0.0);
    let side = (!cameras.is_empty()).then(|| {
        cameras
            .iter()
            .map(|c| {
                let d = u * Vector3::new(c[0] as f64, c[1] as f64, c[2] as f64) - centre;
                Vector3::new(d.x, d.y, 0.0)
                    .try_normalize(1e-12)
                    .unwrap_or_default()
            })
            .sum::<Vector3<f64>>()
            .try_normalize(1e-12)
    });
    let side = side.flatten();
    let frame_of = |yaw: f64| -> Result<ScanFrame, EngineError> {
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw);
        let (lo, hi) = xy_bounds(lifted.iter().map(|p| {
            let q = r * p;
            [q.x, q.y]
        }));
        let t = [-(lo[0] + hi[0]) / 2.0, -(lo[1] + hi[1]) / 2.0, -floor];
        ScanFrame::new(up.into(), yaw, t).map_err(|e| invalid("frame", "finite", e.to_string()))
    };
    let yaw0 = match yaw0 {
        // Planes, or a rectangular footprint with the camera or some face evidence.
        Some(y) if by_planes || side.is_some() || planar.len() >= MIN_FACE_POINTS => Some(y),
        _ => None,
    };
    let Some(yaw0) = yaw0 else {
        let Some(side) = side else {
            return Err(invalid(
                "points",
                &format!(
                    "a scan with vertical planes (at least {MIN_PLANE_SHARE} of its points) to find the yaw, or a camera; or {HINT}"
                ),
                format!("{:.3} of the points on vertical planes", plane_share),
            ));
        };
        // The front (−X) faces the camera: rotate the camera's side onto −X.
        let yaw = std::f64::consts::PI - side.y.atan2(side.x);
        return Ok(FrameEstimate {
            frame: frame_of(yaw)?,
            floor,
            plane_share,
            hypotheses: Vec::new(),
            chosen: 0,
            source: YawSource::Camera,
        });
    };
    // In the aligned frame (rotated by −yaw₀) the planes face ±X and ±Y. Face f's points:
    // normal within 30° of the face's axis, position within FACE_BAND of that side of the box.
    let align = Rotation3::from_axis_angle(&Vector3::z_axis(), -yaw0);
    let aligned: Vec<(Vector3<f64>, f64)> = planar
        .iter()
        .map(|&(p, phi)| (align * p, phi - yaw0))
        .collect();
    let (alo, ahi) = xy_bounds(lifted.iter().map(|p| {
        let q = align * p;
        [q.x, q.y]
    }));
    let band = FACE_BAND * (ahi[0] - alo[0]).hypot(ahi[1] - alo[1]);
    // Faces in order k: −X, +Y, +X, −Y (the face hypothesis k puts at the front: a yaw of
    // k·90° − yaw₀ rotates face k onto −X).
    let faces: [(usize, f64); 4] = [(0, -1.0), (1, 1.0), (0, 1.0), (1, -1.0)];
    let cos30 = 30f64.to_radians().cos();
    // Each face's points (count) and their median depth behind the box's side (relief).
    let diag = (ahi[0] - alo[0]).hypot(ahi[1] - alo[1]).max(1e-12);
    let (counts, reliefs): (Vec<f64>, Vec<f64>) = faces
        .iter()
        .map(|&(axis, sign)| {
            let mut depths: Vec<f64> = aligned
                .iter()
                .filter_map(|&(p, phi)| {
                    let n = [phi.cos(), phi.sin()];
                    let depth = if sign < 0.0 {
                        p[axis] - alo[axis]
                    } else {
                        ahi[axis] - p[axis]
                    };
                    (n[axis].abs() >= cos30 && depth <= band).then_some(depth)
                })
                .collect();
            let n = depths.len() as f64;
            let relief = if depths.len() >= MIN_FACE_POINTS {
                quantile(&mut depths, 0.5) / diag
            } else {
                0.0
            };
            (n, relief)
        })
        .unzip();
    let relief_total: f64 = reliefs.iter().sum();
    // The faces' say grows with the points on them: full from MIN_PLANE_SHARE of the points
    // on the box's planes (a footprint's yaw from a view of the top has few).
    let evidence = (plane_share / MIN_PLANE_SHARE).min(1.0);
    let total = counts.iter().sum::<f64>().max(1.0);
    let hypotheses: Vec<Hypothesis> = faces
        .iter()
        .zip(counts.iter().zip(&reliefs))
        .enumerate()
        .map(|(k, (&(axis, sign), (&count, &relief)))| {
            let mut normal = Vector3::zeros();
            normal[axis] = sign;
            let normal = align.inverse() * normal;
            let camera = side.map(|s| s.dot(&normal));
            let face_share = count / total;
            let relief = if relief_total > MIN_RELIEF {
                relief / relief_total
            } else {
                0.0
            };
            let yaw =
                (k as f64 * std::f64::consts::FRAC_PI_2 - yaw0).rem_euclid(std::f64::consts::TAU);
            Hypothesis {
                yaw,
                face_share,
                relief,
                camera,
                // A face the camera does not look at cannot be the front it scanned.
                score: if camera.is_some_and(|c| c < MIN_CAMERA_COS) {
                    f64::NEG_INFINITY
                } else {
                    evidence * (face_share + RELIEF_WEIGHT * relief)
                        + CAMERA_WEIGHT * camera.unwrap_or(0.0)
                },
            }
        })
        .collect();
    let chosen = (0..4)
        .max_by(|&a, &b| {
            hypotheses[a]
                .score
                .total_cmp(&hypotheses[b].score)
                .then(b.cmp(&a))
        })
        .unwrap_or(0);
    Ok(FrameEstimate {
        frame: frame_of(hypotheses[chosen].yaw)?,
        floor,
        plane_share,
        hypotheses,
        chosen,
        source: if side.is_some() {
            YawSource::PlanesAndCamera
        } else {
            YawSource::Planes
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::rng::Rng;
    use crate::data::scan::{ScanOptions, scan};
    use crate::eval::real::frame::{MovedUp, frame_error, move_of, moved};
    use crate::mesh::{MeshingOptions, mesh_parts};

    /// Ray-cast scans of the example cabinet and the eight-part object in the paper's protocol,
    /// with their cameras (canonical frame).
    fn scans() -> Vec<(Vec<[f32; 3]>, [f32; 3])> {
        let mut out = Vec::new();
        for (k, obj) in [crate::fixtures::cabinet(), crate::fixtures::eight_part()]
            .iter()
            .enumerate()
        {
            let meshes = mesh_parts(obj, None, &MeshingOptions { resolution: 48 }).unwrap();
            for v in 0..4u64 {
                let mut rng = Rng::fork(11 + k as u64, v);
                let s = scan(&meshes, &mut rng, &ScanOptions::default()).unwrap();
                let e = s.camera.eye;
                out.push((s.points, [e.x as f32, e.y as f32, e.z as f32]));
            }
        }
        out
    }

    #[test]
    fn recovers_yaw_and_floor_of_moved_scans_with_and_without_the_camera() {
        // The floor is the lowest point seen (less half a spacing): the cabinet's door hides
        // the bottom 2 cm of its body from a camera above, the eight-part object's recessed
        // plinth 9 cm, so the floor is held to the lowest seen point, not to z = 0.
        let scans = scans();
        for up in [MovedUp::Z, MovedUp::Y] {
            let (mut with, mut without) = (0, 0);
            for (i, (points, eye)) in scans.iter().enumerate() {
                let m = move_of(&format!("scan{i}"), 7, up);
                let p = moved(&m, points);
                let c = moved(&m, &[*eye]);
                let e = estimate(&p, up.vector(), &c).unwrap();
                let err = frame_error(&m, &e.frame);
                let seen = points
                    .iter()
                    .map(|p| p[2] as f64)
                    .fold(f64::INFINITY, f64::min);
                // Up to 3 cm above it: a lone lowest point (isolated) is not trusted.
                let d = err.floor_m - seen;
                assert!(
                    (-0.01..0.03).contains(&d),
                    "{up:?} scan {i}: {err:?}, {seen}"
                );
                with += usize::from(err.yaw_deg <= 10.0);
                let e = estimate(&p, up.vector(), &[]).unwrap();
                let err = frame_error(&m, &e.frame);
                // Without a camera the yaw is right mod 90° on every scan.
                let off = err.yaw_deg % 90.0;
                assert!(off.min(90.0 - off) <= 10.0, "{up:?} scan {i}: {err:?}");
                without += usize::from(err.yaw_deg <= 10.0);
            }
            // The cabinets are seen from within ±60° of their front: the camera decides the
            // front on all but the most oblique views, the scan alone on most.
            assert!(with >= scans.len() - 1, "{up:?}: {with} of {}", scans.len());
            assert!(
                without * 2 >= scans.len(),
                "{up:?}: {without} of {}",
                scans.len()
            );
        }
    }

    #[test]
    fn canonical_scans_come_out_near_the_identity() {
        for (points, eye) in scans() {
            let e = estimate(&points, [0.0, 0.0, 1.0], &[eye]).unwrap();
            let yaw = e.frame.yaw.to_degrees();
            assert!(yaw.min(360.0 - yaw) <= 10.0, "{e:?}");
            let seen = points
                .iter()
                .map(|p| p[2] as f64)
                .fold(f64::INFINITY, f64::min);
            let d = -e.frame.translation.z - seen;
            assert!((-0.01..0.03).contains(&d), "{e:?}");
        }
    }

    #[test]
    fn refuses_a_bad_up_a_flat_scan_and_a_scan_without_planes() {
        let (points, _) = scans().remove(0);
        for up in [[0.0; 3], [f64::NAN, 0.0, 1.0], [0.0, f64::INFINITY, 0.0]] {
            let e = estimate(&points, up, &[]).unwrap_err().to_string();
            assert!(e.contains("up") && e.contains("non-zero"), "{e}");
        }
        // A flat sheet of points (z = 0): no height to stand on.
        let mut rng = Rng::new(1);
        let flat: Vec<[f32; 3]> = (0..500)
            .map(|_| {
                [
                    rng.range(-0.5, 0.5) as f32,
                    rng.range(-0.5, 0.5) as f32,
                    0.0,
                ]
            })
            .collect();
        let e = estimate(&flat, [0.0, 0.0, 1.0], &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("tall") && e.contains("frame canonical"), "{e}");
        // A sphere: no vertical planes; refused without a camera, the camera decides with one.
        let ball: Vec<[f32; 3]> = (0..800)
            .map(|_| {
                let v =
                    nalgebra::Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()).normalize() * 0.3;
                [v.x as f32, v.y as f32, (v.z + 0.3) as f32]
            })
            .collect();
        let e = estimate(&ball, [0.0, 0.0, 1.0], &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("vertical planes") && e.contains("frame canonical"),
            "{e}"
        );
        // With one, its (round) footprint's rectangle is taken, the face nearest the camera
        // at the front.
        let e = estimate(&ball, [0.0, 0.0, 1.0], &[[-2.0, 0.0, 1.0]]).unwrap();
        assert_eq!(e.source, YawSource::PlanesAndCamera);
        let yaw = e.frame.yaw.to_degrees();
        assert!(yaw.min(360.0 - yaw) <= 45.0, "{yaw}");
        // Points filling a triangular prism: no planar neighbourhoods and a footprint half its
        // rectangle. The camera alone decides, the front square to it.
        let prism: Vec<[f32; 3]> = (0..600)
            .map(|_| {
                let (mut u, mut v) = (rng.uniform(), rng.uniform());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                [
                    (0.6 * u) as f32,
                    (0.6 * v) as f32,
                    rng.range(0.0, 0.5) as f32,
                ]
            })
            .collect();
        let e = estimate(&prism, [0.0, 0.0, 1.0], &[[-2.0, 0.2, 1.0]]).unwrap();
        assert_eq!(e.source, YawSource::Camera);
        assert!(e.hypotheses.is_empty());
        let yaw = e.frame.yaw.to_degrees();
        assert!(yaw.min(360.0 - yaw) < 5.0, "{yaw}");
        let e = estimate(&points[..10], [0.0, 0.0, 1.0], &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("at least"), "{e}");
    }
}
