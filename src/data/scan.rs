//! Partial point-cloud scans, following PhysNAP's test protocol (method.md §8.9, §9 A10).
//!
//! Why it exists: PhysNAP is conditioned on what a depth camera sees of an object. We render
//! such views of our objects to make test and validation clouds, and users can make their own.
//!
//! Protocol, with the ambiguities resolved (A10):
//! - rest state (q = 0) geometry, all parts' meshes together;
//! - one pinhole camera: square image of `image` pixels, vertical field of view `fov_deg`,
//!   looking at the centre of the object's bounding box, up = +Z;
//! - elevation U[30°, 80°] above the horizontal; azimuth U[120°, 240°] measured from +X
//!   counter-clockwise about +Z, so 180° looks at the object's front (which faces −X);
//! - distance U[1, 6] × the bounding-sphere radius (our objects are metric, so distance is
//!   relative to size; PartNet-Mobility objects have radius ≈ 1, where this is the paper's
//!   [1, 6]);
//! - a pose is rejected if any mesh vertex projects outside the image or behind the camera
//!   (object cut by the border), or if the projected bounding box spans less than `min_span`
//!   (50 %) of the image horizontally *or* vertically (the stricter reading); up to
//!   `max_attempts` poses are drawn;
//! - every pixel is ray cast against a BVH of all part meshes; `points` pixels are drawn
//!   uniformly from the object mask (without replacement when the mask is large enough), each
//!   ray through a random point of its pixel; the first hit is the point, in object
//!   coordinates. Points therefore lie exactly on visible surfaces.

use nalgebra::{Point3, Vector3};

use super::DataError;
use super::rng::Rng;
use crate::mesh::TriMesh;
use crate::mesh::bvh::MeshBvh;

/// Scan protocol settings.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanOptions {
    /// Points per scan (the paper's M).
    pub points: usize,
    /// Image width = height in pixels.
    pub image: usize,
    /// Vertical field of view in degrees.
    pub fov_deg: f64,
    /// Elevation range in degrees.
    pub elevation: (f64, f64),
    /// Azimuth range in degrees (180 = looking at the front).
    pub azimuth: (f64, f64),
    /// Distance range in bounding-sphere radii.
    pub distance: (f64, f64),
    /// Minimum fraction of the image the object must span in each direction.
    pub min_span: f64,
    /// Camera poses tried before giving up.
    pub max_attempts: usize,
}

impl Default for ScanOptions {
    fn default() -> Self {
        ScanOptions {
            points: 1000,
            image: 256,
            fov_deg: 45.0,
            elevation: (30.0, 80.0),
            azimuth: (120.0, 240.0),
            distance: (1.0, 6.0),
            min_span: 0.5,
            max_attempts: 500,
        }
    }
}

/// A pinhole camera looking at `target` from `eye`, +Z up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Camera centre (object frame).
    pub eye: Point3<f64>,
    /// Point looked at.
    pub target: Point3<f64>,
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
    /// Image width = height, pixels.
    pub image: usize,
}

impl Camera {
    fn basis(&self) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let fwd = (self.target - self.eye).normalize();
        let right = fwd.cross(&Vector3::z()).normalize();
        let up = right.cross(&fwd);
        (fwd, right, up)
    }

    /// Ray direction (unit) through image coordinates (u, v) in pixels (origin top-left).
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        let (fwd, right, up) = self.basis();
        let f = (self.image as f64 / 2.0) / (self.fov_deg.to_radians() / 2.0).tan();
        let c = self.image as f64 / 2.0;
        (fwd * f + right * (u - c) - up * (v - c)).normalize()
    }

    /// Pixel coordinates of a point; `None` behind the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64)> {
        let (fwd, right, up) = self.basis();
        let d = p - self.eye;
        let z = d.dot(&fwd);
        if z <= 1e-9 {
            return None;
        }
        let f = (self.image as f64 / 2.0) / (self.fov_deg.to_radians() / 2.0).tan();
        let c = self.image as f64 / 2.0;
        Some((c + f * d.dot(&right) / z, c - f * d.dot(&up) / z))
    }
}

/// One partial scan.
#[derive(Debug, Clone)]
pub struct Scan {
    /// Points on visible surfaces, object frame.
    pub points: Vec<[f32; 3]>,
    /// The camera used.
    pub camera: Camera,
    /// Elevation (degrees).
    pub elevation: f64,
    /// Azimuth (degrees).
    pub azimuth: f64,
    /// Distance in bounding-sphere radii.
    pub distance: f64,
    /// Camera poses drawn (1 = the first was accepted).
    pub attempts: usize,
    /// Object pixels in the rendered mask.
    pub mask_pixels: usize,
}

/// Concatenate meshes into one (object frame).
pub fn merge_meshes(meshes: &[TriMesh]) -> TriMesh {
    let mut all = TriMesh::default();
    for m in meshes {
        let base = all.positions.len() as u32;
        all.positions.extend_from_slice(&m.positions);
        all.triangles.extend(
            m.triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
    }
    all
}

/// Render one partial scan of the object made of `meshes` (object frame, rest state).
pub fn scan(meshes: &[TriMesh], rng: &mut Rng, opts: &ScanOptions) -> Result<Scan, DataError> {
    let all = merge_meshes(meshes);
    let Some((lo, hi)) = all.bounds() else {
        return Err(DataError::Option(crate::error::Invalid {
            field: "object".into(),
            limit: "at least one non-empty part mesh".into(),
            value: "no geometry".into(),
        }));
    };
    if opts.points == 0 || opts.image < 16 {
        return Err(DataError::Option(crate::error::Invalid {
            field: "scan".into(),
            limit: "points >= 1 and image >= 16".into(),
            value: format!("points {} image {}", opts.points, opts.image),
        }));
    }
    let lo = Vector3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64);
    let hi = Vector3::new(hi[0] as f64, hi[1] as f64, hi[2] as f64);
    let target = Point3::from((lo + hi) / 2.0);
    let radius = ((hi - lo) / 2.0).norm().max(1e-6);
    let bvh = MeshBvh::new(&all.positions, &all.triangles).map_err(|d| {
        DataError::Option(crate::error::Invalid {
            field: "meshes".into(),
            limit: "valid triangle indices".into(),
            value: d.to_string(),
        })
    })?;
    let verts: Vec<Point3<f64>> = all
        .positions
        .iter()
        .map(|p| Point3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect();
    let size = opts.image as f64;
    for attempt in 1..=opts.max_attempts {
        let el = rng.range(opts.elevation.0, opts.elevation.1);
        let az = rng.range(opts.azimuth.0, opts.azimuth.1);
        let dist = rng.range(opts.distance.0, opts.distance.1);
        let (e, a) = (el.to_radians(), az.to_radians());
        let eye =
            target + radius * dist * Vector3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
        let camera = Camera {
            eye,
            target,
            fov_deg: opts.fov_deg,
            image: opts.image,
        };
        // Framing: every vertex in front of the camera and inside the image, and the object
        // spanning at least min_span of the image both ways.
        let mut framed = true;
        let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for v in &verts {
            match camera.project(v) {
                Some((u, w)) if (0.0..size).contains(&u) && (0.0..size).contains(&w) => {
                    umin = umin.min(u);
                    umax = umax.max(u);
                    vmin = vmin.min(w);
                    vmax = vmax.max(w);
                }
                _ => {
                    framed = false;
                    break;
                }
            }
        }
        if !framed || (umax - umin) < opts.min_span * size || (vmax - vmin) < opts.min_span * size {
            continue;
        }
        // Mask: which pixels see the object.
        let eye32 = [eye.x as f32, eye.y as f32, eye.z as f32];
        let far = (radius * (dist + 2.0) * 2.0) as f32;
        let mask: Vec<usize> = (0..opts.image * opts.image)
            .filter(|&k| {
                let (u, v) = ((k % opts.image) as f64 + 0.5, (k / opts.image) as f64 + 0.5);
                let d = camera.ray(u, v);
                bvh.ray_hit(eye32, [d.x as f32, d.y as f32, d.z as f32], 0.0, far)
                    .is_some()
            })
            .collect();
        if mask.is_empty() {
            continue;
        }
        // Draw pixels: a shuffled order (without replacement) repeated if the mask is small.
        let mut order = mask.clone();
        for i in (1..order.len()).rev() {
            order.swap(i, rng.int(0, i));
        }
        let mut points = Vec::with_capacity(opts.points);
        let mut k = 0usize;
        let mut misses = 0usize;
        while points.len() < opts.points {
            let pix = order[k % order.len()];
            k += 1;
            let u = (pix % opts.image) as f64 + rng.uniform();
            let v = (pix / opts.image) as f64 + rng.uniform();
            let d = camera.ray(u, v);
            let d32 = [d.x as f32, d.y as f32, d.z as f32];
            match bvh.ray_hit(eye32, d32, 0.0, far) {
                Some(hit) => points.push(std::array::from_fn(|a| eye32[a] + d32[a] * hit.t)),
                None => {
                    // A jittered ray can slip past a silhouette; after many, use pixel centres.
                    misses += 1;
                    if misses > 50 * opts.points {
                        break;
                    }
                }
            }
        }
        if points.len() < opts.points {
            continue;
        }
        return Ok(Scan {
            points,
            camera,
            elevation: el,
            azimuth: az,
            distance: dist,
            attempts: attempt,
            mask_pixels: mask.len(),
        });
    }
    Err(DataError::Option(crate::error::Invalid {
        field: "scan".into(),
        limit: format!(
            "a well-framed camera pose within {} attempts",
            opts.max_attempts
        ),
        value: "none found (object too thin or too large for the field of view?)".into(),
    }))
}
