//! One URDF (or one subtree of a scene URDF) → one physnap object in the canonical frame.
//!
//! Why it exists: this is where URDF semantics become physnap's: link frames composed at rest
//! (`T_child = T_parent · origin`), joint axes given in the child frame, fixed links merged
//! into their parent, geometry (meshes with `scale`, exact primitive meshes) placed by its
//! `origin`, and the whole object rotated by `--up/--front`, centred in x/y and put on the
//! floor (z = 0). Problems that belong to one asset (missing meshes, loops, several parents,
//! no movable joint, more than 8 parts) are returned as [`Broken`]: the caller skips the
//! object, records the reason and keeps going.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Matrix4, Point3, Vector3};

use super::model::{GeomShape, JointType, Robot};
use crate::mesh::primitives::append_primitive;
use crate::mesh::{TriMesh, obj, stl};
use crate::object::{JOINT_RANGE_TOL, JointKind, MAX_PARTS};
use crate::shape::{Axis, Primitive};

/// Which geometry of each link to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeometrySource {
    /// `<visual>` (default).
    Visual,
    /// `<collision>`.
    Collision,
}

impl GeometrySource {
    /// The URDF element name.
    pub fn as_str(self) -> &'static str {
        match self {
            GeometrySource::Visual => "visual",
            GeometrySource::Collision => "collision",
        }
    }
}

/// A merged part: the links it holds and its mesh (canonical frame, rest state).
#[derive(Debug, Clone)]
pub struct BuiltPart {
    /// URDF link names, the moving (or root) link first.
    pub links: Vec<String>,
    /// Mesh, canonical frame.
    pub mesh: TriMesh,
}

/// A movable joint between merged parts (canonical frame).
#[derive(Debug, Clone)]
pub struct BuiltJoint {
    /// URDF joint name.
    pub name: String,
    /// URDF joint type.
    pub urdf_type: JointType,
    /// Parent part index.
    pub parent: usize,
    /// Child part index.
    pub child: usize,
    /// physnap kind (revolute or prismatic).
    pub kind: JointKind,
    /// Unit axis.
    pub axis: Vector3<f64>,
    /// A point on the axis.
    pub origin: Point3<f64>,
    /// Range: radians (revolute) or metres (prismatic).
    pub range: [f64; 2],
}

/// The object cut out of a URDF.
#[derive(Debug, Clone)]
pub struct BuiltObject {
    /// Parts; part 0 is the base.
    pub parts: Vec<BuiltPart>,
    /// Joints, one per non-base part, in part order.
    pub joints: Vec<BuiltJoint>,
    /// Source frame (URDF root frame of the file) → canonical frame.
    pub to_canonical: Matrix4<f64>,
    /// Non-fatal notes.
    pub notes: Vec<String>,
}

/// What to build.
#[derive(Debug, Clone)]
pub struct BuildSpec {
    /// Link that becomes the base (`None`: the URDF's root link).
    pub subtree: Option<String>,
    /// Geometry source.
    pub geometry: GeometrySource,
    /// Rotation source → canonical (from `--up/--front`).
    pub rotation: Matrix3<f64>,
    /// Range given to continuous joints (radians).
    pub continuous_range: [f64; 2],
    /// Links where the walk stops (the roots of the other subtrees cut from the same file):
    /// they and their descendants belong to their own objects.
    pub stop_at: Vec<String>,
}

/// Why an asset cannot become a physnap object: the importer skips it with this reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Broken {
    /// Several parents, a loop, several or no roots.
    #[error("{0}")]
    NotATree(String),
    /// `--subtree` names a link the file does not have.
    #[error("no link named {0:?}")]
    NoSuchLink(String),
    /// A floating or planar joint.
    #[error(
        "joint {joint:?} is {kind} (physnap models revolute, continuous, prismatic and fixed joints)"
    )]
    UnsupportedJoint {
        /// Joint name.
        joint: String,
        /// URDF type.
        kind: &'static str,
    },
    /// Every joint is fixed (or has an empty range).
    #[error("no movable joint ({links} links, all fixed)")]
    NoMovableJoint {
        /// Links in the object.
        links: usize,
    },
    /// More parts than physnap's graph holds.
    #[error("{parts} parts after merging fixed links (at most {MAX_PARTS})")]
    TooManyParts {
        /// Parts after merging.
        parts: usize,
    },
    /// A mesh file that does not exist.
    #[error("missing mesh {filename:?} (link {link:?}, line {line})")]
    MissingMesh {
        /// The filename attribute.
        filename: String,
        /// The link.
        link: String,
        /// Line of the `<visual>`/`<collision>`.
        line: usize,
    },
    /// A mesh file that cannot be read.
    #[error("mesh {path}: {detail}")]
    BadMesh {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// A part without geometry of the chosen kind.
    #[error("part {part} (links {links}) has no {geometry} geometry")]
    NoGeometry {
        /// Part index.
        part: usize,
        /// Its links, comma-separated.
        links: String,
        /// "visual" or "collision".
        geometry: &'static str,
    },
}

/// Parent joint per link (`None` for roots), or why the links do not form a tree.
pub fn parent_joints(robot: &Robot) -> Result<Vec<Option<usize>>, Broken> {
    let n = robot.links.len();
    let mut parent: Vec<Option<usize>> = vec![None; n];
    for (k, j) in robot.joints.iter().enumerate() {
        let c = robot
            .link_index(&j.child)
            .ok_or_else(|| Broken::NoSuchLink(j.child.clone()))?;
        if let Some(prev) = parent[c] {
            return Err(Broken::NotATree(format!(
                "link {:?} has more than one parent (joints {:?} and {:?}): a kinematic loop, not a tree",
                j.child, robot.joints[prev].name, j.name
            )));
        }
        parent[c] = Some(k);
    }
    for start in 0..n {
        let (mut cur, mut steps) = (start, 0);
        while let Some(k) = parent[cur] {
            cur = robot
                .link_index(&robot.joints[k].parent)
                .ok_or_else(|| Broken::NoSuchLink(robot.joints[k].parent.clone()))?;
            steps += 1;
            if steps > n {
                return Err(Broken::NotATree(format!(
                    "joints form a kinematic loop through link {:?}",
                    robot.links[start].name
                )));
            }
        }
    }
    Ok(parent)
}

/// Resolve a URDF mesh filename relative to the URDF file.
pub fn resolve_mesh(urdf: &Path, filename: &str) -> Option<PathBuf> {
    let dir = urdf.parent().unwrap_or(Path::new("."));
    if let Some(rest) = filename.strip_prefix("file://") {
        let p = PathBuf::from(rest);
        return p.is_file().then_some(p);
    }
    if let Some(rest) = filename.strip_prefix("package://") {
        // package://PKG/sub/path: look for PKG/sub/path or sub/path next to the URDF and in
        // its ancestors (ROS packages keep urdf/ and meshes/ side by side).
        let (pkg, sub) = rest.split_once('/').unwrap_or(("", rest));
        for anc in dir.ancestors().take(6) {
            for cand in [anc.join(pkg).join(sub), anc.join(sub)] {
                if cand.is_file() {
                    return Some(cand);
                }
            }
        }
        return None;
    }
    let p = dir.join(filename);
    p.is_file().then_some(p)
}

/// Read a mesh file (OBJ or STL, by extension).
pub fn load_mesh(path: &Path) -> Result<TriMesh, Broken> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let bad = |detail: String| Broken::BadMesh {
        path: path.to_path_buf(),
        detail,
    };
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let mesh = match ext.as_str() {
        "stl" => stl::parse(&bytes).map_err(|e| e.to_string()),
        "obj" => String::from_utf8(bytes)
            .map_err(|_| "not UTF-8 text".to_string())
            .and_then(|t| obj::parse(&t).map_err(|e| e.to_string())),
        other => Err(format!(
            "unsupported mesh format {other:?} (physnap reads .obj and .stl)"
        )),
    };
    mesh.map_err(bad)
}

/// A part's mesh in the source frame, before the canonical transform (f64 positions).
type SourceMesh = (Vec<Vector3<f64>>, Vec<[u32; 3]>);

fn transform(iso: &Isometry3<f64>, p: [f32; 3]) -> Vector3<f64> {
    (iso * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)).coords
}

/// Build one object. `cache` keeps meshes read for earlier objects of the same run.
pub fn build(
    robot: &Robot,
    spec: &BuildSpec,
    cache: &mut HashMap<PathBuf, TriMesh>,
) -> Result<BuiltObject, Broken> {
    let parent = parent_joints(robot)?;
    let root = match &spec.subtree {
        Some(name) => robot
            .link_index(name)
            .ok_or_else(|| Broken::NoSuchLink(name.clone()))?,
        None => {
            let roots: Vec<usize> = (0..robot.links.len())
                .filter(|&l| parent[l].is_none())
                .collect();
            match roots.as_slice() {
                [r] => *r,
                [] => return Err(Broken::NotATree("no root link".into())),
                many => {
                    let names: Vec<&str> =
                        many.iter().map(|&l| robot.links[l].name.as_str()).collect();
                    return Err(Broken::NotATree(format!(
                        "{} root links ({}): not one kinematic tree",
                        many.len(),
                        names.join(", ")
                    )));
                }
            }
        }
    };
    let link_of = |name: &str| robot.link_index(name).unwrap_or(usize::MAX);
    // Pose of a link in the file's root frame at rest (walks up; the tree has no loop).
    let pose_in_file = |mut l: usize| -> Isometry3<f64> {
        let mut t = Isometry3::identity();
        while let Some(k) = parent[l] {
            t = robot.joints[k].origin * t;
            l = link_of(&robot.joints[k].parent);
        }
        t
    };
    let mut notes = Vec::new();

    // Breadth-first over the subtree, children in joint order; merge fixed links.
    let mut order = vec![root];
    let mut pose: HashMap<usize, Isometry3<f64>> = HashMap::from([(root, pose_in_file(root))]);
    let mut node_of: HashMap<usize, usize> = HashMap::from([(root, 0)]);
    let mut parts = vec![BuiltPart {
        links: vec![robot.links[root].name.clone()],
        mesh: TriMesh::default(),
    }];
    let mut joints_src = Vec::new(); // (joint index, parent node, child node)
    let mut head = 0;
    while head < order.len() {
        let l = order[head];
        head += 1;
        for (k, j) in robot.joints.iter().enumerate() {
            if j.parent != robot.links[l].name {
                continue;
            }
            if spec.stop_at.contains(&j.child) {
                continue;
            }
            let c = link_of(&j.child);
            pose.insert(c, pose[&l] * j.origin);
            if j.mimic {
                notes.push(format!(
                    "joint {:?}: <mimic> ignored (imported as an independent joint)",
                    j.name
                ));
            }
            let range = match j.kind {
                JointType::Floating | JointType::Planar => {
                    return Err(Broken::UnsupportedJoint {
                        joint: j.name.clone(),
                        kind: j.kind.as_str(),
                    });
                }
                JointType::Fixed => None,
                JointType::Continuous => Some(spec.continuous_range),
                JointType::Revolute | JointType::Prismatic => j.limit,
            };
            let movable = match range {
                Some(r) if (r[1] - r[0]).abs() > JOINT_RANGE_TOL => true,
                Some(_) => {
                    notes.push(format!(
                        "joint {:?}: {} with an empty range, merged as fixed",
                        j.name,
                        j.kind.as_str()
                    ));
                    false
                }
                None => false,
            };
            if j.axis_norm != 1.0 && movable {
                notes.push(format!(
                    "joint {:?}: axis of length {} normalised",
                    j.name, j.axis_norm
                ));
            }
            if movable {
                node_of.insert(c, parts.len());
                joints_src.push((k, node_of[&l], parts.len()));
                parts.push(BuiltPart {
                    links: vec![j.child.clone()],
                    mesh: TriMesh::default(),
                });
            } else {
                let n = node_of[&l];
                node_of.insert(c, n);
                parts[n].links.push(j.child.clone());
            }
            order.push(c);
        }
    }
    if parts.len() < 2 {
        return Err(Broken::NoMovableJoint { links: order.len() });
    }
    if parts.len() > MAX_PARTS {
        return Err(Broken::TooManyParts { parts: parts.len() });
    }

    // Geometry in the source frame.
    let mut src_meshes: Vec<SourceMesh> = vec![Default::default(); parts.len()];
    for &l in &order {
        let link = &robot.links[l];
        let geoms = match spec.geometry {
            GeometrySource::Visual => &link.visuals,
            GeometrySource::Collision => &link.collisions,
        };
        let n = node_of[&l];
        for g in geoms {
            let iso = pose[&l] * g.origin;
            let (local, scale): (TriMesh, Vector3<f64>) = match &g.shape {
                GeomShape::Mesh { filename, scale } => {
                    let path =
                        resolve_mesh(&robot.path, filename).ok_or_else(|| Broken::MissingMesh {
                            filename: filename.clone(),
                            link: link.name.clone(),
                            line: g.line,
                        })?;
                    if !cache.contains_key(&path) {
                        let m = load_mesh(&path)?;
                        cache.insert(path.clone(), m);
                    }
                    (cache[&path].clone(), *scale)
                }
                prim => {
                    let p = match prim {
                        GeomShape::Box(size) => Primitive::Cuboid {
                            center: Vector3::zeros(),
                            half_extents: size / 2.0,
                        },
                        GeomShape::Cylinder { radius, length } => Primitive::Cylinder {
                            center: Vector3::zeros(),
                            axis: Axis::Z,
                            radius: *radius,
                            half_height: length / 2.0,
                        },
                        GeomShape::Sphere(r) => Primitive::Sphere {
                            center: Vector3::zeros(),
                            radius: *r,
                        },
                        GeomShape::Mesh { .. } => unreachable!("handled above"),
                    };
                    let mut m = TriMesh::default();
                    append_primitive(&mut m, &p, &Vector3::zeros());
                    (m, Vector3::repeat(1.0))
                }
            };
            // A mirroring scale (odd number of negative factors) flips the winding.
            let flip = scale.iter().filter(|s| **s < 0.0).count() % 2 == 1;
            let (pos, tri) = &mut src_meshes[n];
            let base = pos.len() as u32;
            pos.extend(local.positions.iter().map(|p| {
                let s = [
                    (p[0] as f64 * scale.x) as f32,
                    (p[1] as f64 * scale.y) as f32,
                    (p[2] as f64 * scale.z) as f32,
                ];
                transform(&iso, s)
            }));
            tri.extend(local.triangles.iter().map(|t| {
                if flip {
                    [t[0] + base, t[2] + base, t[1] + base]
                } else {
                    [t[0] + base, t[1] + base, t[2] + base]
                }
            }));
        }
    }
    for (n, (pos, tri)) in src_meshes.iter().enumerate() {
        if tri.is_empty() || pos.is_empty() {
            return Err(Broken::NoGeometry {
                part: n,
                links: parts[n].links.join(", "),
                geometry: spec.geometry.as_str(),
            });
        }
    }

    // Canonical frame: rotate, centre in x/y, floor at z = 0.
    let r = spec.rotation;
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for (pos, _) in &src_meshes {
        for p in pos {
            let q = r * p;
            lo = lo.inf(&q);
            hi = hi.sup(&q);
        }
    }
    let t = Vector3::new(-(lo.x + hi.x) / 2.0, -(lo.y + hi.y) / 2.0, -lo.z);
    let to_c = |p: &Vector3<f64>| r * p + t;
    for (part, (pos, tri)) in parts.iter_mut().zip(&src_meshes) {
        part.mesh = TriMesh {
            positions: pos
                .iter()
                .map(|p| {
                    let q = to_c(p);
                    [q.x as f32, q.y as f32, q.z as f32]
                })
                .collect(),
            triangles: tri.clone(),
        };
    }
    let mut joints = Vec::new();
    for (k, pn, cn) in joints_src {
        let j = &robot.joints[k];
        let c = link_of(&j.child);
        let frame = pose[&c];
        let mut axis = r * (frame.rotation * j.axis);
        axis /= axis.norm();
        let origin = Point3::from(to_c(&frame.translation.vector));
        let mut range = match j.kind {
            JointType::Continuous => spec.continuous_range,
            _ => j.limit.unwrap_or([0.0, 0.0]),
        };
        if range[0] > range[1] {
            range.swap(0, 1);
        }
        // Opening goes the positive way: a range reaching further below 0 than above it is
        // the same motion about the reversed axis (q = 0 stays the rest state).
        if -range[0] > range[1] {
            axis = -axis;
            range = [-range[1], -range[0]];
            notes.push(format!(
                "joint {:?}: range mostly below 0, axis reversed to make it [{}, {}]",
                j.name, range[0], range[1]
            ));
        }
        let kind = match j.kind {
            JointType::Prismatic => JointKind::Prismatic,
            _ => JointKind::Revolute,
        };
        joints.push(BuiltJoint {
            name: j.name.clone(),
            urdf_type: j.kind,
            parent: pn,
            child: cn,
            kind,
            axis,
            origin,
            range,
        });
    }
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&t);
    Ok(BuiltObject {
        parts,
        joints,
        to_canonical: m,
        notes,
    })
}
