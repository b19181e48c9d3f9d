//! URDF import: URDF files (or subtrees of a scene URDF) → the training-set layout of
//! `data import --partnet-mobility`.
//!
//! Why it exists: real articulated assets (ROS packages, robot-learning kitchens, MJCF
//! converted by `scripts/mjcf_to_urdf.py`) come as URDF, not as PartNet-Mobility folders.
//! To keep ONE importer pipeline, each URDF object is converted into a PartNet-Mobility-layout
//! folder (`OUT/pm/<id>/`, see [`pm`]) and the existing reader and dataset writer
//! (`data::partnet::read_object`, `data::dataset::import_dir`) run on those folders. Object
//! folders given with `--partnet-mobility` are copied there unchanged and imported alongside.
//!
//! Flow, and what stops what:
//! 1. every URDF is read and checked ([`model`]); a malformed file (XML syntax, missing or bad
//!    attributes, unknown joint type, zero axis, undefined link) is an error naming the file,
//!    line and element, and the run stops **before anything is written**;
//! 2. options are resolved per object (category, `--up/--front`); a bad option also stops the
//!    run before writing;
//! 3. each object is built ([`convert`]); an asset problem (missing mesh, loop, several
//!    parents, no movable joint, > 8 parts) skips that object, with its reason in
//!    `dataset.json` `skipped`;
//! 4. the dataset is imported from `OUT/pm/`, and `dataset.json` gains a `source` record per
//!    object: file, subtree, geometry, up/front and the 4×4 source → canonical transform.
//!
//! Subtrees cut from one file do not overlap: a link named by another `--subtree` (and
//! everything below it) is left out of its ancestors' objects, so a scene whose fixtures
//! hang from one another (the PRPL kitchen) is cut into one object per fixture.
//!
//! Object ids: the URDF file stem; with `--subtree LINK[=ID]`, ID or `<stem>__<LINK>`.
//! Per-object options: `--category`, `--up`, `--front` take `VALUE` (default for all) or
//! `KEY=VALUE`, KEY being an object id, a subtree link or a file stem.

pub mod convert;
pub mod frame;
pub mod model;
pub mod pm;
pub mod xml;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::Matrix4;
use serde_json::{Value, json};

use super::DataError;
use super::dataset::{ImportOptions, ImportReport, import_dir, object_dirs};
use convert::{BuildSpec, GeometrySource};
use frame::SignedAxis;

/// Errors of the URDF importer.
#[derive(Debug, thiserror::Error)]
pub enum UrdfError {
    /// Malformed XML or URDF: file, 1-based line, element.
    #[error("{path}:{line}: <{element}>: {detail}")]
    Xml {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// Element name.
        element: String,
        /// What is wrong.
        detail: String,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A command-line or API option is wrong.
    #[error("invalid {0}")]
    Option(crate::error::Invalid),
    /// The dataset writer failed.
    #[error(transparent)]
    Data(#[from] DataError),
}

impl UrdfError {
    /// A malformed-file error.
    pub fn xml(path: &Path, line: usize, element: &str, detail: impl Into<String>) -> Self {
        UrdfError::Xml {
            path: path.to_path_buf(),
            line,
            element: element.to_string(),
            detail: detail.into(),
        }
    }

    fn option(field: &str, limit: &str, value: impl std::fmt::Display) -> Self {
        UrdfError::Option(crate::error::Invalid {
            field: field.into(),
            limit: limit.into(),
            value: value.to_string(),
        })
    }

    /// Machine-readable error kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            UrdfError::Xml { .. } => "malformed",
            UrdfError::Io { .. } => "io",
            UrdfError::Option(crate::error::Invalid { .. }) => "invalid_option",
            UrdfError::Data(e) => e.error_type(),
        }
    }
}

/// A value given for all objects and/or per object (`VALUE` or `KEY=VALUE`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PerObject {
    /// The value for objects without their own.
    pub default: Option<String>,
    /// (key, value): key = object id, subtree link or file stem.
    pub keyed: Vec<(String, String)>,
}

impl PerObject {
    /// From command-line values `VALUE` / `KEY=VALUE` (the last bare value wins).
    pub fn parse(values: &[String]) -> Self {
        let mut out = PerObject::default();
        for v in values {
            match v.rsplit_once('=') {
                Some((k, val)) => out.keyed.push((k.to_string(), val.to_string())),
                None => out.default = Some(v.clone()),
            }
        }
        out
    }

    fn get(&self, keys: &[&str]) -> Option<&str> {
        for k in keys {
            if let Some((_, v)) = self.keyed.iter().rev().find(|(key, _)| key == k) {
                return Some(v);
            }
        }
        self.default.as_deref()
    }
}

/// URDF import options.
#[derive(Debug, Clone)]
pub struct UrdfOptions {
    /// Visual (default) or collision geometry.
    pub geometry: GeometrySource,
    /// Range of continuous joints, radians (PartNet-Mobility's `noLimit`: [0, 2π]).
    pub continuous_range: [f64; 2],
    /// `LINK` or `LINK=ID`: cut one object per named link (its descendants are the parts).
    pub subtrees: Vec<String>,
    /// Category per object (required for each object).
    pub category: PerObject,
    /// The asset's up axis (default +Z).
    pub up: PerObject,
    /// The asset's front axis (default −X).
    pub front: PerObject,
}

impl Default for UrdfOptions {
    fn default() -> Self {
        UrdfOptions {
            geometry: GeometrySource::Visual,
            continuous_range: [0.0, std::f64::consts::TAU],
            subtrees: Vec::new(),
            category: PerObject::default(),
            up: PerObject::default(),
            front: PerObject::default(),
        }
    }
}

/// What an import with URDFs did.
#[derive(Debug, Clone, Default)]
pub struct UrdfImportReport {
    /// The dataset import (skips include the URDF objects that could not be built).
    pub dataset: ImportReport,
    /// Objects planned (URDF objects + PartNet-Mobility folders).
    pub planned: usize,
}

/// URDF files under `inputs` (files as given; folders searched recursively), sorted per input.
pub fn urdf_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, UrdfError> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), UrdfError> {
        let rd = std::fs::read_dir(dir).map_err(|source| UrdfError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let mut entries: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(&p, out)?;
            } else if p
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
            {
                out.push(p);
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    for i in inputs {
        if i.is_dir() {
            walk(i, &mut out)?;
        } else if i.is_file() {
            out.push(i.clone());
        } else {
            return Err(UrdfError::option(
                "--urdf",
                "an existing file or folder",
                i.display(),
            ));
        }
    }
    Ok(out)
}

fn sanitise(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

struct Plan {
    id: String,
    robot: usize,
    subtree: Option<String>,
    category: String,
    up: SignedAxis,
    front: SignedAxis,
}

fn matrix_rows(m: &Matrix4<f64>) -> Value {
    json!(
        (0..4)
            .map(|r| (0..4).map(|c| m[(r, c)]).collect::<Vec<f64>>())
            .collect::<Vec<_>>()
    )
}

fn copy_dir(src: &Path, dst: &Path) -> Result<(), UrdfError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| UrdfError::Io { path, source }
    };
    std::fs::create_dir_all(dst).map_err(io(dst))?;
    for e in std::fs::read_dir(src).map_err(io(src))? {
        let p = e.map_err(io(src))?.path();
        let to = dst.join(p.file_name().unwrap_or_default());
        if p.is_dir() {
            copy_dir(&p, &to)?;
        } else {
            std::fs::copy(&p, &to).map_err(io(&p))?;
        }
    }
    Ok(())
}

/// Import URDFs (and optionally a folder of PartNet-Mobility objects) into `out`.
pub fn import(
    urdf_inputs: &[PathBuf],
    partnet: Option<&Path>,
    out: &Path,
    uo: &UrdfOptions,
    opts: &ImportOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<UrdfImportReport, UrdfError> {
    let [c0, c1] = uo.continuous_range;
    if !(c0.is_finite() && c1.is_finite() && c1 - c0 > crate::object::JOINT_RANGE_TOL) {
        return Err(UrdfError::option(
            "--continuous-range",
            "two finite numbers LOWER,UPPER with LOWER < UPPER",
            format!("[{c0}, {c1}]"),
        ));
    }
    // 1. Read every URDF; a malformed one stops the run before anything is written.
    let files = urdf_files(urdf_inputs)?;
    let robots: Vec<model::Robot> = files
        .iter()
        .map(|f| model::read(f))
        .collect::<Result<_, _>>()?;

    // 2. Plan objects and resolve their options.
    let subtrees: Vec<(String, Option<String>)> = uo
        .subtrees
        .iter()
        .map(|s| match s.split_once('=') {
            Some((l, id)) => (l.to_string(), Some(id.to_string())),
            None => (s.clone(), None),
        })
        .collect();
    let mut used = vec![false; subtrees.len()];
    let mut plans = Vec::new();
    for (r, robot) in robots.iter().enumerate() {
        let stem = robot
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| robot.name.clone());
        let cuts: Vec<(String, String)> = subtrees
            .iter()
            .enumerate()
            .filter(|(_, (l, _))| robot.link_index(l).is_some())
            .map(|(k, (l, id))| {
                used[k] = true;
                let id = id.clone().unwrap_or_else(|| format!("{stem}__{l}"));
                (l.clone(), id)
            })
            .collect();
        let objects: Vec<(Option<String>, String)> = if cuts.is_empty() {
            vec![(None, stem.clone())]
        } else {
            cuts.into_iter().map(|(l, id)| (Some(l), id)).collect()
        };
        for (subtree, id) in objects {
            let id = sanitise(&id);
            let keys: Vec<&str> = [Some(id.as_str()), subtree.as_deref(), Some(stem.as_str())]
                .into_iter()
                .flatten()
                .collect();
            let category = uo.category.get(&keys).ok_or_else(|| {
                UrdfError::option(
                    "--category",
                    "given for every object (CATEGORY, or ID=CATEGORY)",
                    format!("none for {id}"),
                )
            })?;
            let category = super::categories::canonical_name(category)
                .ok_or_else(|| {
                    UrdfError::option(
                        "--category",
                        "a physnap category (data::categories)",
                        category,
                    )
                })?
                .to_string();
            let axis =
                |p: &PerObject, field: &str, default: &str| -> Result<SignedAxis, UrdfError> {
                    let v = p.get(&keys).unwrap_or(default);
                    SignedAxis::parse(v)
                        .ok_or_else(|| UrdfError::option(field, "one of +X -X +Y -Y +Z -Z", v))
                };
            let up = axis(&uo.up, "--up", "+Z")?;
            let front = axis(&uo.front, "--front", "-X")?;
            if frame::canonical_rotation(up, front).is_none() {
                return Err(UrdfError::option(
                    "--front",
                    "perpendicular to --up",
                    format!("{front} with --up {up} for {id}"),
                ));
            }
            plans.push(Plan {
                id,
                robot: r,
                subtree,
                category,
                up,
                front,
            });
        }
    }
    if let Some(k) = used.iter().position(|u| !u) {
        return Err(UrdfError::option(
            "--subtree",
            "a link of one of the URDF files",
            &subtrees[k].0,
        ));
    }
    let pm_dirs = match partnet {
        Some(p) => object_dirs(p)?,
        None => Vec::new(),
    };
    let mut ids: HashMap<String, String> = HashMap::new();
    let names = plans
        .iter()
        .map(|p| (p.id.clone(), robots[p.robot].path.display().to_string()))
        .chain(pm_dirs.iter().map(|d| {
            (
                d.file_name()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                d.display().to_string(),
            )
        }));
    for (id, from) in names {
        if let Some(prev) = ids.insert(id.clone(), from.clone()) {
            return Err(UrdfError::option(
                "object ids",
                "unique (use --subtree LINK=ID or rename a file)",
                format!("{id} from both {prev} and {from}"),
            ));
        }
    }
    if plans.is_empty() && pm_dirs.is_empty() {
        return Err(UrdfError::option(
            "--urdf",
            "at least one URDF file",
            "none found",
        ));
    }

    // 3. Build and stage every object; broken assets are skipped with a reason.
    let stage = out.join("pm");
    if stage.exists() {
        std::fs::remove_dir_all(&stage).map_err(|source| UrdfError::Io {
            path: stage.clone(),
            source,
        })?;
    }
    std::fs::create_dir_all(&stage).map_err(|source| UrdfError::Io {
        path: stage.clone(),
        source,
    })?;
    let mut skipped = Vec::new();
    let mut notes = Vec::new();
    let mut sources: HashMap<String, Value> = HashMap::new();
    let mut cache = HashMap::new();
    for plan in &plans {
        let robot = &robots[plan.robot];
        let spec = BuildSpec {
            subtree: plan.subtree.clone(),
            geometry: uo.geometry,
            rotation: frame::canonical_rotation(plan.up, plan.front)
                .unwrap_or_else(nalgebra::Matrix3::identity),
            continuous_range: uo.continuous_range,
            stop_at: subtrees
                .iter()
                .map(|(l, _)| l.clone())
                .filter(|l| Some(l) != plan.subtree.as_ref() && robot.link_index(l).is_some())
                .collect(),
        };
        match convert::build(robot, &spec, &mut cache) {
            Err(reason) => skipped.push((plan.id.clone(), reason.to_string())),
            Ok(obj) => {
                let source = json!({
                    "format": "urdf",
                    "file": robot.path.display().to_string(),
                    "robot": robot.name,
                    "subtree": plan.subtree,
                    "geometry": uo.geometry.as_str(),
                    "up": plan.up.to_string(),
                    "front": plan.front.to_string(),
                    "to_canonical": matrix_rows(&obj.to_canonical),
                    "to_canonical_note": "4x4 row-major; maps the URDF file's root frame (metres) to physnap's canonical frame (+Z up, front -X, floor z = 0, centred in x/y)",
                    "parts": obj.parts.iter().map(|p| json!({ "links": p.links })).collect::<Vec<_>>(),
                    "joints": obj.joints.iter().map(|j| json!({
                        "name": j.name, "urdf_type": j.urdf_type.as_str(), "parent": j.parent,
                        "child": j.child, "range": j.range,
                    })).collect::<Vec<_>>(),
                });
                pm::write_object(&obj, &plan.id, &plan.category, &source, &stage)?;
                for n in &obj.notes {
                    notes.push((plan.id.clone(), n.clone()));
                }
                sources.insert(plan.id.clone(), source);
            }
        }
    }
    let raw_to_world = {
        let c = |v: [f64; 3]| super::partnet::raw_to_world(v);
        let (x, y, z) = (c([1.0, 0.0, 0.0]), c([0.0, 1.0, 0.0]), c([0.0, 0.0, 1.0]));
        let mut m = Matrix4::identity();
        for (col, v) in [x, y, z].iter().enumerate() {
            for row in 0..3 {
                m[(row, col)] = v[row];
            }
        }
        m
    };
    for d in &pm_dirs {
        let id = d
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        copy_dir(d, &stage.join(&id))?;
        sources.insert(
            id,
            json!({
                "format": "partnet-mobility",
                "folder": d.display().to_string(),
                "to_canonical": matrix_rows(&raw_to_world),
                "to_canonical_note": "PartNet-Mobility raw Y-up frame to physnap's object frame (the importer's fixed mapping; PartNet-Mobility units, not rescaled)",
            }),
        );
    }

    // 4. One importer pipeline over the staged folders.
    let mut report = import_dir(&stage, out, opts, progress)?;
    report.skipped.extend(skipped);
    report.skipped.sort();
    report.notes.extend(notes);
    report.notes.sort();
    let index_path = out.join("dataset.json");
    let io = |source| UrdfError::Io {
        path: index_path.clone(),
        source,
    };
    let mut index: Value = serde_json::from_str(&std::fs::read_to_string(&index_path).map_err(io)?)
        .map_err(|e| {
            UrdfError::Data(DataError::Malformed {
                path: index_path.clone(),
                detail: e.to_string(),
            })
        })?;
    if let Some(objs) = index["objects"].as_array_mut() {
        for o in objs {
            let id = o["id"].as_str().unwrap_or_default().to_string();
            if let Some(s) = sources.get(&id) {
                o["source"] = s.clone();
            }
        }
    }
    index["skipped"] = json!(
        report
            .skipped
            .iter()
            .map(|(id, r)| json!({ "id": id, "reason": r }))
            .collect::<Vec<_>>()
    );
    index["notes"] = json!(
        report
            .notes
            .iter()
            .map(|(id, n)| json!({ "id": id, "note": n }))
            .collect::<Vec<_>>()
    );
    index["staged"] = json!("pm");
    std::fs::write(
        &index_path,
        serde_json::to_string_pretty(&index).unwrap_or_default(),
    )
    .map_err(|source| UrdfError::Io {
        path: index_path.clone(),
        source,
    })?;
    Ok(UrdfImportReport {
        planned: plans.len() + pm_dirs.len(),
        dataset: report,
    })
}
