//! Data pipeline acceptance: procedural objects are valid and deterministic, the
//! PartNet-Mobility importer round-trips them (and survives real-data quirks), SDF labels agree
//! with the meshes, and scans lie on visible surfaces.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use physnap::data::categories::SYNTH_CATEGORIES;
use physnap::data::dataset::{ImportOptions, import_dir, load_object_meshes};
use physnap::data::generate::{SynthOptions, synthesize};
use physnap::data::partnet::read_object;
use physnap::data::rng::Rng;
use physnap::data::scan::{ScanOptions, merge_meshes, scan};
use physnap::data::validity;
use physnap::graph::{GraphTensor, project};
use physnap::io::npy;
use physnap::mesh::bvh::MeshBvh;
use physnap::shape::{AnalyticSdf, PartShape, Sdf};

fn synth(dir: &Path, objects: usize, seed: u64) -> physnap::data::generate::SynthReport {
    synthesize(
        dir,
        &SynthOptions {
            objects,
            seed,
            categories: SYNTH_CATEGORIES.iter().map(|s| s.to_string()).collect(),
            max_attempts: 200,
        },
        &|_, _| {},
    )
    .unwrap()
}

fn tree_digest(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

#[test]
fn synth_covers_categories_is_valid_and_deterministic() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let n = 3 * SYNTH_CATEGORIES.len();
    let report = synth(a.path(), n, 11);
    assert_eq!(report.written, n, "failures: {:?}", report.failed);
    assert_eq!(report.per_category.len(), SYNTH_CATEGORIES.len());
    assert!(report.part_histogram.keys().all(|k| (2..=8).contains(k)));
    synth(b.path(), n, 11);
    let (da, db) = (tree_digest(a.path()), tree_digest(b.path()));
    assert_eq!(da.keys().collect::<Vec<_>>(), db.keys().collect::<Vec<_>>());
    for (k, v) in &da {
        assert!(
            db[k] == *v,
            "{} differs between two runs with the same seed",
            k.display()
        );
    }
    // Every written object passes the validity checks.
    for i in 0..n {
        let shapes = a.path().join(format!("{i:06}/physnap_shapes.json"));
        let obj = physnap::io::object_json::read(&shapes).unwrap();
        validity::check(&obj, &Default::default()).unwrap_or_else(|v| panic!("object {i}: {v}"));
    }
    // A different seed gives different objects.
    let c = tempfile::tempdir().unwrap();
    synth(c.path(), 3, 12);
    assert_ne!(
        std::fs::read(a.path().join("000000/physnap_shapes.json")).unwrap(),
        std::fs::read(c.path().join("000000/physnap_shapes.json")).unwrap()
    );
}

#[test]
fn import_round_trips_through_projection_and_sdf_signs_match_meshes() {
    let src = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    // Three objects per category, so every category has a train, val and test object.
    let n = 3 * SYNTH_CATEGORIES.len();
    synth(src.path(), n, 5);
    let opts = ImportOptions {
        seed: 1,
        uniform: 2000,
        near: 500,
        surface: 256,
    };
    let report = import_dir(src.path(), out.path(), &opts, &|_, _| {}).unwrap();
    assert!(report.skipped.is_empty(), "{:?}", report.skipped);
    assert_eq!(report.entries.len(), n);
    for split in ["train", "val", "test"] {
        assert!(
            report.entries.iter().any(|e| e.split == split),
            "empty {split} split"
        );
    }
    let mut agree = 0usize;
    let mut total = 0usize;
    for e in &report.entries {
        let dir = out.path().join("objects").join(&e.id);
        // The graph record projects back to the same object.
        let (rows, cols, flat) = npy::read(&dir.join("graph.npy")).unwrap();
        assert_eq!((rows, cols), (1, physnap::graph::FLAT_DIM));
        let g = GraphTensor::from_flat(&flat).unwrap();
        let back = project(&g, &Default::default()).unwrap();
        let (imported, _) = load_object_meshes(&dir).unwrap();
        // The synthetic source, with fixed children merged, is what the importer must produce.
        let source =
            physnap::io::object_json::read(&src.path().join(&e.id).join("physnap_shapes.json"))
                .unwrap();
        let (merged, _) = source.merge_fixed().unwrap();
        assert_eq!(imported.parts.len(), merged.parts.len(), "{}", e.id);
        assert_eq!(back.parts.len(), imported.parts.len(), "{}", e.id);
        for (a, b) in imported.parts.iter().zip(&merged.parts) {
            assert!(
                (a.center - b.center).norm() < 1e-9
                    && (a.half_extents - b.half_extents).norm() < 1e-9
            );
        }
        for j in &imported.joints {
            let k = back
                .joints
                .iter()
                .position(|x| {
                    (x.parent == j.parent && x.child == j.child)
                        || (x.parent == j.child && x.child == j.parent)
                })
                .unwrap_or_else(|| panic!("{}: joint {}-{} lost", e.id, j.parent, j.child));
            let x = &back.joints[k];
            assert_eq!(x.kind, j.kind, "{}", e.id);
            let sign = if x.parent == j.parent { 1.0 } else { -1.0 };
            assert!((x.axis * sign - j.axis).norm() < 1e-5, "{}: axis", e.id);
            for i in 0..2 {
                assert!(
                    (x.revolute[i] - j.revolute[i]).abs() < 1e-5,
                    "{}: revolute limits",
                    e.id
                );
                assert!(
                    (x.prismatic[i] - j.prismatic[i]).abs() < 1e-5,
                    "{}: prismatic limits",
                    e.id
                );
            }
        }
        // The stored SDF samples' signs agree with the part meshes (winding-number inside test).
        for (k, part) in imported.parts.iter().enumerate() {
            let mesh = physnap::mesh::obj::parse(
                &std::fs::read_to_string(dir.join(format!("part{k}.obj"))).unwrap(),
            )
            .unwrap();
            let bvh = MeshBvh::new(&mesh.positions, &mesh.triangles).unwrap();
            let (rows, cols, data) = npy::read(&dir.join(format!("part{k}_uniform.npy"))).unwrap();
            assert_eq!((rows, cols), (2000, 4));
            let prims = match &part.shape {
                PartShape::Primitives(p) => p.as_slice(),
                _ => &[],
            };
            let analytic = AnalyticSdf {
                primitives: prims,
                half_extents: part.half_extents,
                kappa: part.kappa(),
            };
            for row in data.chunks_exact(4) {
                let p = [row[0], row[1], row[2]];
                let mut exact = [0f32];
                analytic.eval_batch(&[p], &mut exact);
                assert!(
                    (exact[0] - row[3]).abs() < 1e-6,
                    "stored SDF is the analytic SDF"
                );
                if exact[0].abs() < 1e-3 {
                    continue; // too close to the surface to call
                }
                total += 1;
                agree += usize::from(bvh.is_inside(p) == (row[3] < 0.0));
            }
        }
    }
    let rate = agree as f64 / total as f64;
    assert!(
        rate >= 0.995,
        "analytic SDF and mesh agree on sign at {:.4} of {total} points",
        rate
    );
}

#[test]
fn scans_lie_on_visible_surfaces() {
    let src = tempfile::tempdir().unwrap();
    synth(src.path(), 6, 9);
    for i in 0..6 {
        let obj = read_object(&src.path().join(format!("{i:06}"))).unwrap();
        let mut rng = Rng::new(i);
        let s = scan(&obj.meshes, &mut rng, &ScanOptions::default()).unwrap();
        assert_eq!(s.points.len(), 1000);
        let all = merge_meshes(&obj.meshes);
        let bvh = MeshBvh::new(&all.positions, &all.triangles).unwrap();
        let eye = [
            s.camera.eye.x as f32,
            s.camera.eye.y as f32,
            s.camera.eye.z as f32,
        ];
        for p in &s.points {
            let (q, d2, tri) = bvh.closest_point(*p).unwrap();
            if d2.sqrt() >= 1e-4 {
                let dir: [f32; 3] = std::array::from_fn(|a| p[a] - eye[a]);
                let h = bvh.ray_hit(eye, dir, 0.0, 2.0);
                let t = all.triangles[tri as usize];
                let v: Vec<_> = t.iter().map(|&i| all.positions[i as usize]).collect();
                panic!(
                    "tri verts {v:?} point {p:?} is {} from the surface (closest {q:?} tri {tri}); eye {eye:?}; re-hit {h:?}",
                    d2.sqrt()
                );
            }
            // Visible: nothing between the camera and the point.
            let dir: [f32; 3] = std::array::from_fn(|a| p[a] - eye[a]);
            assert!(
                !bvh.ray_occluded(eye, dir, 0.0, 1.0 - 1e-4),
                "point {p:?} is hidden"
            );
        }
        // The framing rule held: elevation/azimuth within the protocol's ranges.
        assert!((30.0..=80.0).contains(&s.elevation) && (120.0..=240.0).contains(&s.azimuth));
        // Deterministic.
        let again = scan(&obj.meshes, &mut Rng::new(i), &ScanOptions::default()).unwrap();
        assert_eq!(again.points, s.points);
    }
}

fn edit_json(path: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(path, v.to_string()).unwrap();
}

#[test]
fn importer_handles_partnet_mobility_quirks() {
    let src = tempfile::tempdir().unwrap();
    // Use several categories so some objects have hinges and some sliders.
    synth(src.path(), SYNTH_CATEGORIES.len(), 3);
    let dir = |i: usize| src.path().join(format!("{i:06}"));
    // Real PM folders have no physnap_shapes.json: geometry comes from the OBJ meshes.
    for i in 0..SYNTH_CATEGORIES.len() {
        std::fs::remove_file(dir(i).join("physnap_shapes.json")).unwrap();
    }
    // 0: a null axis direction -> skipped with a reason.
    edit_json(&dir(0).join("mobility_v2.json"), |v| {
        let e = v
            .as_array_mut()
            .unwrap()
            .iter_mut()
            .find(|e| e["jointData"]["axis"].is_object())
            .unwrap();
        e["jointData"]["axis"]["direction"] = serde_json::json!([null, 1, 0]);
    });
    // 1: a missing meta.json -> skipped.
    std::fs::remove_file(dir(1).join("meta.json")).unwrap();
    // 2: an OBJ listed in result.json is missing (its link keeps other meshes) -> imported
    // with a note.
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir(2).join("result.json")).unwrap())
            .unwrap();
    let leaf = result[0]["children"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["objs"].as_array().unwrap().len() >= 2)
        .expect("a part made of several primitives");
    let gone = leaf["objs"][0].as_str().unwrap();
    std::fs::remove_file(dir(2).join(format!("textured_objs/{gone}.obj"))).unwrap();
    // 3: a second root (a link with ≥ 3 links in the object) -> merged into the first, noted.
    let links = |i: usize| -> usize {
        let v: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir(i).join("mobility_v2.json")).unwrap(),
        )
        .unwrap();
        v.as_array().unwrap().len()
    };
    let two_roots = (6..SYNTH_CATEGORIES.len())
        .find(|&i| links(i) >= 4)
        .expect("an object with 4+ links");
    edit_json(&dir(two_roots).join("mobility_v2.json"), |v| {
        let list = v.as_array_mut().unwrap();
        let parent_ids: Vec<i64> = list.iter().map(|e| e["parent"].as_i64().unwrap()).collect();
        // A leaf link (nobody's parent) becomes a second root.
        let k = (0..list.len())
            .find(|&k| {
                parent_ids[k] != -1 && !parent_ids.contains(&list[k]["id"].as_i64().unwrap())
            })
            .unwrap();
        list[k]["parent"] = (-1).into();
        list[k]["joint"] = "free".into();
    });
    // 4: a corrupted limit string -> skipped with a reason naming the field.
    edit_json(&dir(4).join("mobility_v2.json"), |v| {
        let e = v
            .as_array_mut()
            .unwrap()
            .iter_mut()
            .find(|e| e["jointData"]["limit"].is_object())
            .unwrap();
        e["jointData"]["limit"]["b"] = "-z0.008".into();
    });
    // 5: a continuous hinge (noLimit) -> revolute [0, 2π].
    let mut hinge_id = None;
    edit_json(&dir(5).join("mobility_v2.json"), |v| {
        if let Some(e) = v
            .as_array_mut()
            .unwrap()
            .iter_mut()
            .find(|e| e["joint"] == "hinge")
        {
            e["jointData"]["limit"]["noLimit"] = true.into();
            hinge_id = e["id"].as_i64();
        }
    });

    let report = physnap::data::dataset::import_dir(
        src.path(),
        &tempfile::tempdir().unwrap().path().join("o"),
        &ImportOptions {
            uniform: 64,
            near: 64,
            surface: 64,
            ..Default::default()
        },
        &|_, _| {},
    )
    .unwrap();
    let skipped: BTreeMap<_, _> = report.skipped.iter().cloned().collect();
    assert!(
        skipped["000000"].contains("axis direction is null"),
        "{skipped:?}"
    );
    assert!(skipped["000001"].contains("meta.json"), "{skipped:?}");
    assert!(skipped["000004"].contains("limit.b"), "{skipped:?}");
    assert!(
        report
            .notes
            .iter()
            .any(|(id, n)| id == "000002" && n.contains("missing mesh"))
    );
    let two_roots = format!("{two_roots:06}");
    assert!(
        report
            .notes
            .iter()
            .any(|(id, n)| *id == two_roots && n.contains("2 roots")),
        "{:?} {:?}",
        report.notes,
        report.skipped
    );
    assert_eq!(
        report.entries.len() + report.skipped.len(),
        SYNTH_CATEGORIES.len()
    );
    if hinge_id.is_some() {
        let o = read_object(&dir(5)).unwrap();
        assert!(
            o.object
                .joints
                .iter()
                .any(|j| j.revolute == [0.0, std::f64::consts::TAU])
        );
    }
}

#[test]
fn hinge_limits_are_read_in_degrees() {
    let src = tempfile::tempdir().unwrap();
    synth(src.path(), SYNTH_CATEGORIES.len(), 21);
    for i in 0..SYNTH_CATEGORIES.len() {
        let d = src.path().join(format!("{i:06}"));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("mobility_v2.json")).unwrap())
                .unwrap();
        let o = read_object(&d).unwrap();
        for e in v
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["joint"] == "hinge")
        {
            let b = e["jointData"]["limit"]["b"].as_f64().unwrap();
            assert!(
                o.object
                    .joints
                    .iter()
                    .any(|j| (j.revolute[1] - b.to_radians()).abs() < 1e-9),
                "object {i}: {b} degrees"
            );
        }
    }
}
