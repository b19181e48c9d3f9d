//! The articulated-object JSON: a lossless, human-editable exchange format.
//!
//! Why it exists: the service, the CLI and tests exchange objects (projection results, generated
//! samples, hand-written examples) as files; `physnap export --object obj.json` turns one into
//! GLB + URDF. The schema (`"format": "physnap.object/v1"`):
//!
//! ```json
//! { "format": "physnap.object/v1", "name": "cabinet", "category": "StorageFurniture",
//!   "parts": [ { "name": "body", "half_extents": [0.3, 0.25, 0.4], "center": [0, 0, 0.4],
//!                "shape": { "type": "box" } } ],
//!   "joints": [ { "parent": "body", "child": "door", "type": "revolute",
//!                 "axis": [0, 0, 1], "origin": [0.3, -0.25, 0.4], "revolute": [0, 1.57] } ] }
//! ```
//!
//! Shapes: `{"type": "box"}`, `{"type": "latent", "code": [128 floats]}`, or
//! `{"type": "primitives", "primitives": [{"type": "cuboid", "center", "half_extents"} |
//! {"type": "sphere", "center", "radius"} | {"type": "cylinder", "center", "axis": "x|y|z",
//! "radius", "half_height"}]}`. Joint parents/children are part *names*; `axis` is normalised
//! on read; a missing range is [0, 0]. Unknown fields are rejected (typos surface as errors).
//! Values are f64 and written with Rust's shortest round-trip formatting, so
//! read(write(x)) == x exactly.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::FormatError;
use crate::error::CoreError;
use crate::frame::ScanFrame;
use crate::graph::repair::Repair;
use crate::object::{ArticulatedObject, Joint, JointKind, Part};
use crate::shape::{Axis, PartShape, Primitive};

/// The format tag written into every document.
pub const FORMAT: &str = "physnap.object/v1";

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectDoc {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    format: Option<String>,
    name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    category: Option<String>,
    parts: Vec<PartDoc>,
    #[serde(default)]
    joints: Vec<JointDoc>,
    /// What generation's joint repair changed (graph::repair): informational, accepted and
    /// dropped on read.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    repairs: Vec<RepairDoc>,
    /// The physics check of the export's collision pieces (`io::verdict::sim_json`):
    /// informational, accepted and dropped on read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sim: Option<serde_json::Value>,
    /// The scan's frame (`crate::frame`; omitted for canonical output): `mode`, `up`, `yaw`
    /// (radians), `yaw_degrees`, `translation` (scan → canonical: p_c = R p_s + t) and
    /// `to_scan` (canonical → scan, 4×4 row-major). Read back by [`frame_from_str`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frame: Option<FrameDoc>,
    /// The parts (centre, rotation, half extents) and joints (axis, origin) in the scan's
    /// frame: informational, accepted and dropped on read (`parts` and `joints` above stay in
    /// the canonical frame, the one physnap reads).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    scan_frame: Option<serde_json::Value>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameDoc {
    mode: String,
    up: [f64; 3],
    yaw: f64,
    yaw_degrees: f64,
    translation: [f64; 3],
    to_scan: [[f64; 4]; 4],
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RepairDoc {
    joint: String,
    rule: String,
    amount: f64,
    detail: String,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PartDoc {
    name: String,
    half_extents: [f64; 3],
    center: [f64; 3],
    #[serde(default = "box_shape")]
    shape: ShapeDoc,
}

fn box_shape() -> ShapeDoc {
    ShapeDoc::Box
}

#[derive(Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum ShapeDoc {
    Box,
    Latent { code: Vec<f32> },
    Primitives { primitives: Vec<PrimitiveDoc> },
}

#[derive(Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum PrimitiveDoc {
    Cuboid {
        center: [f64; 3],
        half_extents: [f64; 3],
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    Cylinder {
        center: [f64; 3],
        axis: AxisDoc,
        radius: f64,
        half_height: f64,
    },
}

#[derive(Serialize, Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum AxisDoc {
    X,
    Y,
    Z,
}

#[derive(Serialize, Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum KindDoc {
    Revolute,
    Prismatic,
    Screw,
    Fixed,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct JointDoc {
    parent: String,
    child: String,
    #[serde(rename = "type")]
    kind: KindDoc,
    axis: [f64; 3],
    origin: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    revolute: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    prismatic: Option<[f64; 2]>,
}

/// Parse and validate an object JSON document.
pub fn from_str(text: &str) -> Result<ArticulatedObject, FormatError> {
    let de = &mut serde_json::Deserializer::from_str(text);
    let doc: ObjectDoc = serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        FormatError::Malformed {
            what: "object JSON",
            path,
            message: e.into_inner().to_string(),
        }
    })?;
    let obj = from_doc(doc)?;
    obj.validate()?;
    Ok(obj)
}

/// Read and validate an object JSON file.
pub fn read(path: &std::path::Path) -> Result<ArticulatedObject, FormatError> {
    let text = std::fs::read_to_string(path).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })?;
    from_str(&text)
}

/// Serialise a (valid) object to pretty JSON.
pub fn to_string(obj: &ArticulatedObject) -> String {
    to_string_with_repairs(obj, &[])
}

/// [`to_string`] with the joint repairs generation made, as `"repairs": [{"joint": <child
/// part>, "rule", "amount", "detail"}]` (omitted when empty).
pub fn to_string_with_repairs(obj: &ArticulatedObject, repairs: &[Repair]) -> String {
    to_string_with(obj, repairs, None, None)
}

/// The scan's frame of an object JSON document (None: canonical, no `"frame"`).
pub fn frame_from_str(text: &str) -> Result<Option<ScanFrame>, FormatError> {
    #[derive(Deserialize)]
    struct Only {
        #[serde(default)]
        frame: Option<FrameDoc>,
    }
    let doc: Only = serde_json::from_str(text).map_err(|e| FormatError::Malformed {
        what: "object JSON",
        path: "frame".into(),
        message: e.to_string(),
    })?;
    doc.frame
        .map(|f| ScanFrame::new(f.up, f.yaw, f.translation).map_err(FormatError::from))
        .transpose()
}

/// `obj`'s parts and joints in the scan's frame of `f` (module docs of `crate::frame`).
fn scan_frame_json(obj: &ArticulatedObject, f: &ScanFrame) -> serde_json::Value {
    let iso = f.to_scan();
    let rot = iso.rotation.to_rotation_matrix();
    let m = rot.matrix();
    let rows: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]));
    let p3 = |p: Point3<f64>| -> [f64; 3] { (iso * p).coords.into() };
    serde_json::json!({
        "note": "parts and joints of this document in the scan's frame: a part is its box (half_extents) rotated by rotation (row-major) about center",
        "parts": obj.parts.iter().map(|p| serde_json::json!({
            "name": p.name,
            "center": p3(Point3::from(p.center)),
            "rotation": rows,
            "half_extents": <[f64; 3]>::from(p.half_extents),
        })).collect::<Vec<_>>(),
        "joints": obj.joints.iter().map(|j| serde_json::json!({
            "parent": obj.parts[j.parent].name,
            "child": obj.parts[j.child].name,
            "type": j.kind.as_str(),
            "axis": <[f64; 3]>::from(rot * j.axis),
            "origin": p3(j.origin),
        })).collect::<Vec<_>>(),
    })
}

/// [`to_string_with_repairs`] with the export's physics check as `"sim"` (the document of
/// [`crate::io::verdict::sim_json`]) and the scan's frame (`"frame"`, `"scan_frame"`; none for
/// None or the identity).
pub fn to_string_with(
    obj: &ArticulatedObject,
    repairs: &[Repair],
    sim: Option<serde_json::Value>,
    frame: Option<&ScanFrame>,
) -> String {
    let mut doc = to_doc(obj);
    doc.sim = sim;
    if let Some(f) = frame.filter(|f| !f.is_canonical()) {
        doc.frame = Some(FrameDoc {
            mode: "auto".into(),
            up: f.up.into(),
            yaw: f.yaw,
            yaw_degrees: f.yaw.to_degrees(),
            translation: f.translation.into(),
            to_scan: f.to_scan_matrix(),
        });
        doc.scan_frame = Some(scan_frame_json(obj, f));
    }
    doc.repairs = repairs
        .iter()
        .map(|r| RepairDoc {
            joint: r.child.clone(),
            rule: r.rule.as_str().into(),
            amount: r.amount,
            detail: r.detail.clone(),
        })
        .collect();
    // Serialising plain structs of numbers and strings cannot fail.
    serde_json::to_string_pretty(&doc).unwrap_or_default()
}

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

fn from_doc(doc: ObjectDoc) -> Result<ArticulatedObject, CoreError> {
    if let Some(f) = &doc.format
        && f != FORMAT
    {
        return Err(CoreError::invalid(
            "format",
            format!("{FORMAT:?}"),
            format!("{f:?}"),
        ));
    }
    let parts: Vec<Part> = doc
        .parts
        .into_iter()
        .map(|p| Part {
            name: p.name,
            half_extents: v3(p.half_extents),
            center: v3(p.center),
            shape: match p.shape {
                ShapeDoc::Box => PartShape::Box,
                ShapeDoc::Latent { code } => PartShape::Latent(code),
                ShapeDoc::Primitives { primitives } => {
                    PartShape::Primitives(primitives.into_iter().map(primitive).collect())
                }
            },
        })
        .collect();
    let index = |field: String, name: &str| {
        parts
            .iter()
            .position(|p| p.name == name)
            .ok_or_else(|| CoreError::invalid(field, "the name of a part", format!("{name:?}")))
    };
    let mut joints = Vec::with_capacity(doc.joints.len());
    for (k, j) in doc.joints.iter().enumerate() {
        let axis = v3(j.axis);
        let norm = axis.norm();
        if !(norm.is_finite() && norm > 1e-12) {
            return Err(CoreError::invalid(
                format!("joints[{k}].axis"),
                "a finite non-zero vector",
                format!("{:?}", j.axis),
            ));
        }
        joints.push(Joint {
            parent: index(format!("joints[{k}].parent"), &j.parent)?,
            child: index(format!("joints[{k}].child"), &j.child)?,
            kind: match j.kind {
                KindDoc::Revolute => JointKind::Revolute,
                KindDoc::Prismatic => JointKind::Prismatic,
                KindDoc::Screw => JointKind::Screw,
                KindDoc::Fixed => JointKind::Fixed,
            },
            // Already-unit axes are kept bit-exact, so write → read round-trips exactly.
            axis: if (norm - 1.0).abs() <= 4.0 * f64::EPSILON {
                axis
            } else {
                axis / norm
            },
            origin: Point3::from(j.origin),
            revolute: j.revolute.unwrap_or([0.0, 0.0]),
            prismatic: j.prismatic.unwrap_or([0.0, 0.0]),
        });
    }
    Ok(ArticulatedObject {
        name: doc.name,
        category: doc.category,
        parts,
        joints,
    })
}

fn primitive(p: PrimitiveDoc) -> Primitive {
    match p {
        PrimitiveDoc::Cuboid {
            center,
            half_extents,
        } => Primitive::Cuboid {
            center: v3(center),
            half_extents: v3(half_extents),
        },
        PrimitiveDoc::Sphere { center, radius } => Primitive::Sphere {
            center: v3(center),
            radius,
        },
        PrimitiveDoc::Cylinder {
            center,
            axis,
            radius,
            half_height,
        } => Primitive::Cylinder {
            center: v3(center),
            axis: match axis {
                AxisDoc::X => Axis::X,
                AxisDoc::Y => Axis::Y,
                AxisDoc::Z => Axis::Z,
            },
            radius,
            half_height,
        },
    }
}

fn a3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn to_doc(obj: &ArticulatedObject) -> ObjectDoc {
    let name_of = |i: usize| obj.parts.get(i).map(|p| p.name.clone()).unwrap_or_default();
    ObjectDoc {
        format: Some(FORMAT.into()),
        name: obj.name.clone(),
        category: obj.category.clone(),
        parts: obj
            .parts
            .iter()
            .map(|p| PartDoc {
                name: p.name.clone(),
                half_extents: a3(&p.half_extents),
                center: a3(&p.center),
                shape: match &p.shape {
                    PartShape::Box => ShapeDoc::Box,
                    PartShape::Latent(code) => ShapeDoc::Latent { code: code.clone() },
                    PartShape::Primitives(prims) => ShapeDoc::Primitives {
                        primitives: prims.iter().map(primitive_doc).collect(),
                    },
                },
            })
            .collect(),
        joints: obj
            .joints
            .iter()
            .map(|j| JointDoc {
                parent: name_of(j.parent),
                child: name_of(j.child),
                kind: match j.kind {
                    JointKind::Revolute => KindDoc::Revolute,
                    JointKind::Prismatic => KindDoc::Prismatic,
                    JointKind::Screw => KindDoc::Screw,
                    JointKind::Fixed => KindDoc::Fixed,
                },
                axis: a3(&j.axis),
                origin: a3(&j.origin.coords),
                revolute: j.kind.rotates().then_some(j.revolute),
                prismatic: j.kind.slides().then_some(j.prismatic),
            })
            .collect(),
        repairs: Vec::new(),
        sim: None,
        frame: None,
        scan_frame: None,
    }
}

fn primitive_doc(p: &Primitive) -> PrimitiveDoc {
    match p {
        Primitive::Cuboid {
            center,
            half_extents,
        } => PrimitiveDoc::Cuboid {
            center: a3(center),
            half_extents: a3(half_extents),
        },
        Primitive::Sphere { center, radius } => PrimitiveDoc::Sphere {
            center: a3(center),
            radius: *radius,
        },
        Primitive::Cylinder {
            center,
            axis,
            radius,
            half_height,
        } => PrimitiveDoc::Cylinder {
            center: a3(center),
            axis: match axis {
                Axis::X => AxisDoc::X,
                Axis::Y => AxisDoc::Y,
                Axis::Z => AxisDoc::Z,
            },
            radius: *radius,
            half_height: *half_height,
        },
    }
}
