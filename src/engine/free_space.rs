//! Free space from the camera (real-scans.md §5): what a depth sensor saw *through*.
//!
//! ```text
//! camera c, scan point p:  q_k = c + s_k (p − c),  s_k ∈ (0, 1 − m/|p − c|)   (empty space)
//! m = MARGIN_FRACTION · the cloud's box diagonal
//! ```
//!
//! Why it exists: ℓ_pc only pulls surfaces onto observed points, so nothing stopped a part from
//! filling space the camera looked through. Two users share this geometry: the guidance term
//! ℓ_free ([`super::guidance::free`]) penalises parts at the [`samples`], and the part filter
//! ([`super::prune`]) asks [`FreeSpace::seen_through`] whether a part's surface lies in space
//! the camera saw empty.
//!
//! Several cameras: a point is only paired with a camera that could see it. A pair (c, p) is
//! dropped when another scan point lies on nearly the same ray from c (within the scan's
//! angular spacing) and more than m closer to c: p was hidden from c, so the ray c → p says
//! nothing. One camera sees all its points by construction.

/// Most cameras a request may carry.
pub const MAX_CAMERAS: usize = 16;
/// Rays per camera ℓ_free samples (every ⌈M / this⌉-th point, so the cost does not grow with
/// the cloud).
pub const RAYS_PER_CAMERA: usize = 256;
/// Free-space samples per ray (the s_k, evenly spaced, midpoints).
pub const SAMPLES_PER_RAY: usize = 8;
/// m: the free stretch of a ray stops this fraction of the cloud's box diagonal short of its
/// point, so the surface the point lies on is not itself "free".
pub const MARGIN_FRACTION: f32 = 0.01;
/// The angular tolerance of "the same ray" is this many times the scan's median angular
/// spacing (nearest-neighbour angle of the points as the camera sees them).
pub const ANGLE_FACTOR: f32 = 1.5;
/// Points used to estimate the angular spacing and to test visibility (a stride of the cloud).
const MAX_REFERENCE_POINTS: usize = 2048;

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(a: [f32; 3]) -> f32 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// The diagonal of the points' axis-aligned box (0 for fewer than 2 distinct points).
pub fn extent(points: &[[f32; 3]]) -> f32 {
    let (lo, hi) = bounds(points);
    norm(sub(hi, lo)).max(0.0)
}

/// The points' axis-aligned box (lo, hi); (+∞, −∞) for no points.
pub fn bounds(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Every `stride`-th point so that at most `n` remain.
fn strided(points: &[[f32; 3]], n: usize) -> Vec<[f32; 3]> {
    let stride = points.len().div_ceil(n.max(1)).max(1);
    points.iter().step_by(stride).copied().collect()
}

/// One camera's view of the scan: unit directions and depths of the reference points.
struct View {
    camera: [f32; 3],
    dirs: Vec<[f32; 3]>,
    depths: Vec<f32>,
    /// cos of the angular tolerance.
    cos_tol: f32,
}

impl View {
    fn new(camera: [f32; 3], reference: &[[f32; 3]]) -> View {
        let mut dirs = Vec::with_capacity(reference.len());
        let mut depths = Vec::with_capacity(reference.len());
        for &p in reference {
            let d = sub(p, camera);
            let r = norm(d).max(1e-9);
            dirs.push(d.map(|v| v / r));
            depths.push(r);
        }
        // Median nearest-neighbour angle (as the largest dot product).
        let mut nn: Vec<f32> = dirs
            .iter()
            .enumerate()
            .map(|(i, a)| {
                dirs.iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, b)| a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
                    .fold(-1.0f32, f32::max)
                    .clamp(-1.0, 1.0)
                    .acos()
            })
            .collect();
        let spacing = if nn.is_empty() {
            0.0
        } else {
            let mid = nn.len() / 2;
            *nn.select_nth_unstable_by(mid, f32::total_cmp).1
        };
        // At least 0.2° so a very dense or degenerate cloud still has a tolerance.
        let tol = (ANGLE_FACTOR * spacing).max(0.2f32.to_radians());
        View {
            camera,
            dirs,
            depths,
            cos_tol: tol.cos(),
        }
    }

    /// Whether some reference point lies within the tolerance of the ray to `x` and more than
    /// `margin` beyond (`beyond = true`) or before (`beyond = false`) `x`.
    fn any_on_ray(&self, x: [f32; 3], margin: f32, beyond: bool) -> bool {
        let d = sub(x, self.camera);
        let r = norm(d);
        if r <= 1e-9 {
            return false;
        }
        let u = d.map(|v| v / r);
        self.dirs.iter().zip(&self.depths).any(|(a, &depth)| {
            let near = a[0] * u[0] + a[1] * u[1] + a[2] * u[2] >= self.cos_tol;
            near && if beyond {
                depth > r + margin
            } else {
                depth < r - margin
            }
        })
    }
}

/// The scan's free space: the cloud, its cameras and the margin m.
pub struct FreeSpace {
    views: Vec<View>,
    margin: f32,
    /// (camera, point) rays that carry free space, each point as seen by a camera that could
    /// see it (strided to [`RAYS_PER_CAMERA`] per camera).
    rays: Vec<([f32; 3], [f32; 3])>,
}

impl FreeSpace {
    /// The free space of `points` seen from `cameras` (none: an empty free space).
    pub fn new(points: &[[f32; 3]], cameras: &[[f32; 3]]) -> FreeSpace {
        let margin = MARGIN_FRACTION * extent(points);
        if points.is_empty() || cameras.is_empty() {
            return FreeSpace {
                views: Vec::new(),
                margin,
                rays: Vec::new(),
            };
        }
        let reference = strided(points, MAX_REFERENCE_POINTS);
        let views: Vec<View> = cameras.iter().map(|&c| View::new(c, &reference)).collect();
        let candidates = strided(points, RAYS_PER_CAMERA);
        let mut rays = Vec::new();
        for v in &views {
            for &p in &candidates {
                // With one camera every point was seen by it; with several, drop the points
                // another point hides from this camera.
                if cameras.len() == 1 || !v.any_on_ray(p, margin, false) {
                    rays.push((v.camera, p));
                }
            }
        }
        FreeSpace {
            views,
            margin,
            rays,
        }
    }

    /// Whether there is any free space (a camera and a point).
    pub fn is_empty(&self) -> bool {
        self.rays.is_empty()
    }

    /// The margin m (metres).
    pub fn margin(&self) -> f32 {
        self.margin
    }

    /// The free-space samples q_k: [`SAMPLES_PER_RAY`] per ray at the midpoints of equal
    /// steps of s ∈ (0, 1 − m/|p − c|).
    pub fn samples(&self) -> Vec<[f32; 3]> {
        let mut out = Vec::with_capacity(self.rays.len() * SAMPLES_PER_RAY);
        for &(c, p) in &self.rays {
            let d = sub(p, c);
            let r = norm(d);
            if r <= self.margin {
                continue;
            }
            let s_max = 1.0 - self.margin / r;
            for k in 0..SAMPLES_PER_RAY {
                let s = s_max * (k as f32 + 0.5) / SAMPLES_PER_RAY as f32;
                out.push([c[0] + s * d[0], c[1] + s * d[1], c[2] + s * d[2]]);
            }
        }
        out
    }

    /// Whether `x` lies in space some camera saw through: a scan point on (nearly) the same ray
    /// from that camera lies more than m beyond `x`.
    pub fn seen_through(&self, x: [f32; 3]) -> bool {
        self.views
            .iter()
            .any(|v| v.any_on_ray(x, self.margin, true))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10 × 10 grid of points on the plane x = 1, |y|, |z| ≤ 0.45.
    fn wall() -> Vec<[f32; 3]> {
        (0..10)
            .flat_map(|i| (0..10).map(move |j| [1.0, i as f32 * 0.1 - 0.45, j as f32 * 0.1 - 0.45]))
            .collect()
    }

    #[test]
    fn samples_lie_between_camera_and_points() {
        let pts = wall();
        let fs = FreeSpace::new(&pts, &[[-1.0, 0.0, 0.0]]);
        let s = fs.samples();
        assert_eq!(s.len(), pts.len() * SAMPLES_PER_RAY);
        assert!(
            s.iter()
                .all(|q| q[0] > -1.0 && q[0] < 1.0 - 0.5 * fs.margin())
        );
        assert!(fs.seen_through([0.0, 0.0, 0.0]));
        // Behind the wall, beside it, and on it: not seen through.
        assert!(!fs.seen_through([1.5, 0.0, 0.0]));
        assert!(!fs.seen_through([0.0, 3.0, 0.0]));
        assert!(!fs.seen_through([1.0, 0.05, 0.05]));
        assert!(FreeSpace::new(&pts, &[]).samples().is_empty());
    }

    #[test]
    fn a_hidden_point_carries_no_ray_from_a_second_camera() {
        // A near wall hides a far point from the camera at −x; the camera at +y sees it.
        let mut pts = wall();
        pts.push([2.0, 0.0, 0.0]);
        let one = FreeSpace::new(&pts, &[[-1.0, 0.0, 0.0]]);
        assert_eq!(one.rays.len(), pts.len());
        let two = FreeSpace::new(&pts, &[[-1.0, 0.0, 0.0], [2.0, 3.0, 0.0]]);
        let hidden = two
            .rays
            .iter()
            .filter(|(c, p)| *c == [-1.0, 0.0, 0.0] && *p == [2.0, 0.0, 0.0])
            .count();
        assert_eq!(hidden, 0);
        assert!(
            two.rays
                .iter()
                .any(|(c, p)| *c == [2.0, 3.0, 0.0] && *p == [2.0, 0.0, 0.0])
        );
    }
}
