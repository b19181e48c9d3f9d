//! The URDF elements physnap reads: links with visual/collision geometry, and joints.
//!
//! Why it exists: the importer needs a checked, typed view of a URDF before it touches any
//! mesh or writes any file, so that a malformed file fails as a whole with its file, line and
//! element (and nothing is written for it), while asset problems found later (a missing mesh,
//! a loop) only skip one object. Everything the URDF spec requires and physnap relies on is
//! checked here: names, joint types, parent/child links that exist, numbers, non-zero axes,
//! `<limit>` on revolute and prismatic joints, one shape per `<geometry>`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::UrdfError;
use super::xml::{self, Element};

/// A `<geometry>` shape (URDF units: metres).
#[derive(Debug, Clone, PartialEq)]
pub enum GeomShape {
    /// `<mesh filename scale>`.
    Mesh {
        /// The filename attribute as written (`package://`, `file://` or relative).
        filename: String,
        /// Per-axis scale (default 1 1 1).
        scale: Vector3<f64>,
    },
    /// `<box size>`: full edge lengths.
    Box(Vector3<f64>),
    /// `<cylinder radius length>`, along the local Z axis.
    Cylinder {
        /// Radius.
        radius: f64,
        /// Full length.
        length: f64,
    },
    /// `<sphere radius>`.
    Sphere(f64),
}

/// One `<visual>` or `<collision>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Geom {
    /// Pose in the link frame.
    pub origin: Isometry3<f64>,
    /// The shape.
    pub shape: GeomShape,
    /// Line of the `<visual>`/`<collision>` element.
    pub line: usize,
}

/// One `<link>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// Name.
    pub name: String,
    /// Visual geometry.
    pub visuals: Vec<Geom>,
    /// Collision geometry.
    pub collisions: Vec<Geom>,
    /// Line of the `<link>` element.
    pub line: usize,
}

/// URDF joint types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointType {
    /// Hinge with limits.
    Revolute,
    /// Hinge without limits.
    Continuous,
    /// Slider with limits.
    Prismatic,
    /// Rigid.
    Fixed,
    /// 6-DoF (not an articulation physnap models).
    Floating,
    /// 2-D translation (not modelled).
    Planar,
}

impl JointType {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "revolute" => JointType::Revolute,
            "continuous" => JointType::Continuous,
            "prismatic" => JointType::Prismatic,
            "fixed" => JointType::Fixed,
            "floating" => JointType::Floating,
            "planar" => JointType::Planar,
            _ => return None,
        })
    }

    /// The URDF word.
    pub fn as_str(self) -> &'static str {
        match self {
            JointType::Revolute => "revolute",
            JointType::Continuous => "continuous",
            JointType::Prismatic => "prismatic",
            JointType::Fixed => "fixed",
            JointType::Floating => "floating",
            JointType::Planar => "planar",
        }
    }
}

/// One `<joint>`.
#[derive(Debug, Clone, PartialEq)]
pub struct JointDef {
    /// Name.
    pub name: String,
    /// Type.
    pub kind: JointType,
    /// Parent link name.
    pub parent: String,
    /// Child link name.
    pub child: String,
    /// Child frame in the parent frame at q = 0.
    pub origin: Isometry3<f64>,
    /// Unit axis in the joint (child) frame; the file's value normalised.
    pub axis: Vector3<f64>,
    /// Norm of the axis as written (1 for a unit axis).
    pub axis_norm: f64,
    /// `<limit lower upper>` (required for revolute and prismatic).
    pub limit: Option<[f64; 2]>,
    /// Whether the joint has a `<mimic>` (ignored).
    pub mimic: bool,
    /// Line of the `<joint>` element.
    pub line: usize,
}

/// A parsed URDF file.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    /// The file.
    pub path: PathBuf,
    /// `<robot name>`.
    pub name: String,
    /// Links in file order.
    pub links: Vec<Link>,
    /// Joints in file order.
    pub joints: Vec<JointDef>,
}

impl Robot {
    /// Index of the link named `name`.
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }
}

struct Ctx<'a> {
    path: &'a Path,
}

impl Ctx<'_> {
    fn err(&self, e: &Element, detail: impl Into<String>) -> UrdfError {
        UrdfError::xml(self.path, e.line, &e.name, detail)
    }

    fn required<'e>(&self, e: &'e Element, key: &str) -> Result<&'e str, UrdfError> {
        e.attr(key)
            .ok_or_else(|| self.err(e, format!("missing attribute {key}")))
    }

    fn number(&self, e: &Element, key: &str, text: &str) -> Result<f64, UrdfError> {
        text.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                self.err(
                    e,
                    format!("attribute {key}={text:?} is not a finite number"),
                )
            })
    }

    fn vec3(
        &self,
        e: &Element,
        key: &str,
        default: Vector3<f64>,
    ) -> Result<Vector3<f64>, UrdfError> {
        let Some(text) = e.attr(key) else {
            return Ok(default);
        };
        let parts: Vec<&str> = text.split_whitespace().collect();
        if parts.len() != 3 {
            return Err(self.err(e, format!("attribute {key}={text:?} must be 3 numbers")));
        }
        let mut v = Vector3::zeros();
        for (a, p) in parts.iter().enumerate() {
            v[a] = self.number(e, key, p)?;
        }
        Ok(v)
    }

    fn origin(&self, parent: &Element) -> Result<Isometry3<f64>, UrdfError> {
        let Some(o) = parent.child("origin") else {
            return Ok(Isometry3::identity());
        };
        let xyz = self.vec3(o, "xyz", Vector3::zeros())?;
        let rpy = self.vec3(o, "rpy", Vector3::zeros())?;
        Ok(origin_from(xyz, rpy))
    }

    fn geom(&self, g: &Element) -> Result<Geom, UrdfError> {
        let origin = self.origin(g)?;
        let geometry = g
            .child("geometry")
            .ok_or_else(|| self.err(g, "no <geometry>"))?;
        let shapes: Vec<&Element> = geometry
            .children
            .iter()
            .filter(|c| matches!(c.name.as_str(), "mesh" | "box" | "cylinder" | "sphere"))
            .collect();
        let [s] = shapes.as_slice() else {
            return Err(self.err(
                geometry,
                format!(
                    "must hold exactly one of <mesh>, <box>, <cylinder>, <sphere> (found {})",
                    shapes.len()
                ),
            ));
        };
        let positive = |v: f64, key: &str| -> Result<f64, UrdfError> {
            if v > 0.0 {
                Ok(v)
            } else {
                Err(self.err(s, format!("{key} must be > 0 (got {v})")))
            }
        };
        let shape = match s.name.as_str() {
            "mesh" => GeomShape::Mesh {
                filename: self.required(s, "filename")?.to_string(),
                scale: self.vec3(s, "scale", Vector3::repeat(1.0))?,
            },
            "box" => {
                let size = self.vec3(s, "size", Vector3::zeros())?;
                if s.attr("size").is_none() {
                    return Err(self.err(s, "missing attribute size"));
                }
                for a in 0..3 {
                    positive(size[a], "size")?;
                }
                GeomShape::Box(size)
            }
            "cylinder" => GeomShape::Cylinder {
                radius: positive(
                    self.number(s, "radius", self.required(s, "radius")?)?,
                    "radius",
                )?,
                length: positive(
                    self.number(s, "length", self.required(s, "length")?)?,
                    "length",
                )?,
            },
            _ => GeomShape::Sphere(positive(
                self.number(s, "radius", self.required(s, "radius")?)?,
                "radius",
            )?),
        };
        Ok(Geom {
            origin,
            shape,
            line: g.line,
        })
    }
}

/// URDF `origin` (xyz, rpy = fixed-axis roll about X, pitch about Y, yaw about Z).
pub fn origin_from(xyz: Vector3<f64>, rpy: Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(xyz),
        UnitQuaternion::from_euler_angles(rpy.x, rpy.y, rpy.z),
    )
}

/// Parse a URDF document (already read into `root`, from `path`).
pub fn from_element(path: &Path, root: &Element) -> Result<Robot, UrdfError> {
    let cx = Ctx { path };
    if root.name != "robot" {
        return Err(cx.err(root, "the root element must be <robot>"));
    }
    let mut links = Vec::new();
    let mut seen: HashMap<String, usize> = HashMap::new();
    for l in root.children_named("link") {
        let name = cx.required(l, "name")?.to_string();
        if let Some(line) = seen.insert(name.clone(), l.line) {
            return Err(cx.err(
                l,
                format!("link name {name:?} is already used (line {line})"),
            ));
        }
        let visuals = l
            .children_named("visual")
            .map(|g| cx.geom(g))
            .collect::<Result<_, _>>()?;
        let collisions = l
            .children_named("collision")
            .map(|g| cx.geom(g))
            .collect::<Result<_, _>>()?;
        links.push(Link {
            name,
            visuals,
            collisions,
            line: l.line,
        });
    }
    let mut joints = Vec::new();
    let mut joint_names: HashMap<String, usize> = HashMap::new();
    for j in root.children_named("joint") {
        let name = cx.required(j, "name")?.to_string();
        if let Some(line) = joint_names.insert(name.clone(), j.line) {
            return Err(cx.err(
                j,
                format!("joint name {name:?} is already used (line {line})"),
            ));
        }
        let word = cx.required(j, "type")?;
        let kind = JointType::parse(word).ok_or_else(|| {
            cx.err(
                j,
                format!(
                    "type {word:?} is not a URDF joint type (revolute, continuous, prismatic, fixed, floating, planar)"
                ),
            )
        })?;
        let link_of = |tag: &str| -> Result<String, UrdfError> {
            let e = j
                .child(tag)
                .ok_or_else(|| cx.err(j, format!("no <{tag}>")))?;
            let l = cx.required(e, "link")?;
            if !seen.contains_key(l) {
                return Err(cx.err(e, format!("link {l:?} is not defined in this file")));
            }
            Ok(l.to_string())
        };
        let parent = link_of("parent")?;
        let child = link_of("child")?;
        let origin = cx.origin(j)?;
        let (axis, axis_norm) = match j.child("axis") {
            Some(a) => {
                let v = cx.vec3(a, "xyz", Vector3::x())?;
                let n = v.norm();
                if n < 1e-12 {
                    return Err(cx.err(a, "axis xyz is the zero vector"));
                }
                (v / n, n)
            }
            None => (Vector3::x(), 1.0),
        };
        let limit = match j.child("limit") {
            Some(l) => {
                let lo = match l.attr("lower") {
                    Some(t) => cx.number(l, "lower", t)?,
                    None => 0.0,
                };
                let hi = match l.attr("upper") {
                    Some(t) => cx.number(l, "upper", t)?,
                    None => 0.0,
                };
                Some([lo, hi])
            }
            None => None,
        };
        if matches!(kind, JointType::Revolute | JointType::Prismatic) && limit.is_none() {
            return Err(cx.err(j, format!("a {word} joint needs a <limit>")));
        }
        joints.push(JointDef {
            name,
            kind,
            parent,
            child,
            origin,
            axis,
            axis_norm,
            limit,
            mimic: j.child("mimic").is_some(),
            line: j.line,
        });
    }
    Ok(Robot {
        path: path.to_path_buf(),
        name: root.attr("name").unwrap_or("robot").to_string(),
        links,
        joints,
    })
}

/// Read and check a URDF file.
pub fn read(path: &Path) -> Result<Robot, UrdfError> {
    let (root, _) = xml::read(path)?;
    from_element(path, &root)
}
