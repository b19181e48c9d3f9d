//! Analytic-SDF and finite-difference tests of the guidance losses.

use burn::tensor::{Int, Tensor, TensorData};
use nalgebra::{Point3, Vector3};

use super::*;
use crate::graph::{GraphTensor, edge_index};
use crate::kinematics::{PluckerLine, screw_transform};
use crate::model::shape_prior::{ShapeDecoder, ShapePriorConfig};
use crate::model::{cpu, cpu_autodiff};
use crate::shape::box_sdf;

const LATENT: usize = 8;

/// Box field plus a small learned-decoder term: exact boxes for the sign tests' intuition, and a
/// real network between codes/points and the SDF for the gradient checks.
struct MixedField {
    decoder: ShapeDecoder,
    scale: f32,
}

impl SdfField for MixedField {
    fn latent(&self) -> usize {
        LATENT
    }
    fn sdf(&self, q: Tensor<2>, codes: Tensor<2>, idx: Tensor<1, Int>) -> Tensor<1> {
        let exact = BoxField { latent: LATENT }.sdf(q.clone(), codes.clone(), idx.clone());
        exact + SdfField::sdf(&self.decoder, q, codes, idx) * self.scale
    }
}

fn mixed() -> MixedField {
    let cfg = ShapePriorConfig {
        latent: LATENT,
        decoder_hidden: 16,
        decoder_blocks: 1,
        encoder_hidden: 8,
        encoder_blocks: 1,
        pe_freqs: 2,
        code_every_block: false,
    };
    let mut rng = Rng::new(11);
    MixedField {
        decoder: ShapeDecoder::new(&cfg, &mut rng, &cpu()),
        scale: 0.05,
    }
}

/// A part whose code makes [`BoxField`] exactly its box: h = b/κ.
fn set_part(g: &mut GraphTensor, i: usize, o: f32, b: [f32; 3], t: [f32; 3]) {
    let kappa = 2.0 * (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
    let row = g.node_mut(i);
    row[node_ch::EXIST] = o;
    row[node_ch::BOX..node_ch::BOX + 3].copy_from_slice(&b);
    row[node_ch::CENTER..node_ch::CENTER + 3].copy_from_slice(&t);
    for k in 0..3 {
        row[node_ch::LATENT + k] = b[k] / kappa;
    }
}

/// Edge (i < j) with class one-hot `class`, line through `point` along `dir`, ranges.
fn set_edge(
    g: &mut GraphTensor,
    i: usize,
    j: usize,
    class: usize,
    point: [f64; 3],
    dir: [f64; 3],
    [rev, pri]: [[f32; 2]; 2],
) {
    let line = PluckerLine::through(&Point3::from(point), &Vector3::from(dir));
    let row = g.edge_mut(edge_index(i, j));
    row[..3].fill(0.0);
    row[class] = 1.0;
    for k in 0..3 {
        row[edge_ch::DIR + k] = line.l[k] as f32;
        row[edge_ch::MOMENT + k] = line.m[k] as f32;
    }
    row[edge_ch::REVOLUTE..edge_ch::REVOLUTE + 2].copy_from_slice(&rev);
    row[edge_ch::PRISMATIC..edge_ch::PRISMATIC + 2].copy_from_slice(&pri);
}

fn tensors(g: &GraphTensor, dev: &burn::tensor::Device) -> (Tensor<2>, Tensor<2>) {
    (
        Tensor::from_data(TensorData::new(g.nodes.clone(), [K, NODE_DIM]), dev),
        Tensor::from_data(TensorData::new(g.edges.clone(), [NUM_EDGES, EDGE_DIM]), dev),
    )
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Term {
    Pc,
    Pen,
    Mob,
}

fn points() -> Vec<[f32; 3]> {
    let mut rng = Rng::new(3);
    (0..40)
        .map(|_| {
            [
                rng.range(-0.6, 0.9) as f32,
                rng.range(-0.5, 0.5) as f32,
                rng.range(-0.5, 0.5) as f32,
            ]
        })
        .collect()
}

/// One term on one graph (plain or autodiff device), as a tensor.
fn term(
    field: &dyn SdfField,
    g: &GraphTensor,
    which: Term,
    dev: &burn::tensor::Device,
) -> Option<Tensor<1>> {
    let (n, e) = tensors(g, dev);
    term_of(field, n, e, which)
}

fn term_of(field: &dyn SdfField, n: Tensor<2>, e: Tensor<2>, which: Term) -> Option<Tensor<1>> {
    let d = decode(n, e, field.latent());
    match which {
        Term::Pc => Some(pc::loss(
            field,
            &d.parts,
            d.exist.clone(),
            &points(),
            1000.0,
        )),
        Term::Pen => pen::loss(field, &d.parts, d.exist.clone(), &d.host),
        Term::Mob => {
            let items = mob::loss_items(&d.classes, &mut Rng::new(5));
            let w = mob::loss_weights(d.edges.clone(), &items);
            mob::sweep(field, &d.parts, d.edges.clone(), &items, w)
        }
    }
}

fn value(field: &dyn SdfField, g: &GraphTensor, which: Term) -> f64 {
    term(field, g, which, &cpu()).map_or(0.0, |t| t.into_scalar::<f32>() as f64)
}

fn two_boxes(gap_x: f32) -> GraphTensor {
    let mut g = GraphTensor::empty();
    set_part(&mut g, 0, 1.0, [0.5, 0.5, 0.5], [0.0, 0.0, 0.0]);
    set_part(&mut g, 1, 1.0, [0.3, 0.3, 0.3], [0.8 + gap_x, 0.1, 0.0]);
    g
}

/// Host reference of ℓ_pen for two exact boxes with unit existences (f64, same grid rule).
fn host_pen(g: &GraphTensor) -> f64 {
    let part = |i: usize| {
        let r = g.node(i);
        let b = Vector3::new(r[1] as f64, r[2] as f64, r[3] as f64);
        let t = Vector3::new(r[4] as f64, r[5] as f64, r[6] as f64);
        (b, t)
    };
    let ((b0, t0), (b1, t1)) = (part(0), part(1));
    let lo = (t0 - b0).sup(&(t1 - b1));
    let hi = (t0 + b0).inf(&(t1 + b1));
    let e = (hi - lo).map(|v| v.max(0.0));
    let Some(n) = grid::axis_counts([e.x as f32, e.y as f32, e.z as f32]) else {
        return 0.0;
    };
    let vel = 1e5 * e.x * e.y * e.z / (n[0] * n[1] * n[2]) as f64;
    let mut sum = 0.0;
    for a in 0..n[0] {
        for b in 0..n[1] {
            for c in 0..n[2] {
                let f = Vector3::new(
                    (a as f64 + 0.5) / n[0] as f64,
                    (b as f64 + 0.5) / n[1] as f64,
                    (c as f64 + 0.5) / n[2] as f64,
                );
                let q = lo + f.component_mul(&e);
                let s = box_sdf(&(q - t0), &b0) + box_sdf(&(q - t1), &b1);
                sum += 0.5 * (-s).max(0.0).powi(2);
            }
        }
    }
    2.0 * vel * sum
}

#[test]
fn penetration_is_positive_when_boxes_overlap_and_zero_apart() {
    let field = BoxField { latent: LATENT };
    let overlapping = two_boxes(-0.2);
    let v = value(&field, &overlapping, Term::Pen);
    let want = host_pen(&overlapping);
    assert!(v > 0.0, "overlap must be penalised: {v}");
    assert!((v - want).abs() < 1e-3 * want, "ℓ_pen {v} vs host {want}");
    // Deeper overlap costs more.
    assert!(value(&field, &two_boxes(-0.4), Term::Pen) > v);
    // Apart: the boxes do not intersect, the pair is skipped.
    let apart = two_boxes(0.1);
    assert!(term(&field, &apart, Term::Pen, &cpu()).is_none());
    // Existence weights: a vanishing part contributes nothing, half existence a quarter.
    let mut half = overlapping.clone();
    half.node_mut(0)[node_ch::EXIST] = 0.5;
    half.node_mut(1)[node_ch::EXIST] = 0.5;
    let vh = value(&field, &half, Term::Pen);
    assert!((vh - 0.25 * v).abs() < 1e-3 * v, "{vh} vs {}", 0.25 * v);
    let mut gone = overlapping;
    gone.node_mut(1)[node_ch::EXIST] = 0.0;
    assert!(term(&field, &gone, Term::Pen, &cpu()).is_none());
}

#[test]
fn point_cloud_loss_is_zero_on_the_surface_and_grows_off_it() {
    let field = BoxField { latent: LATENT };
    let g = two_boxes(1.0);
    // Points on the faces of both boxes.
    let mut pts = Vec::new();
    let mut rng = Rng::new(1);
    for (b, t) in [(0.5f64, [0.0, 0.0, 0.0]), (0.3, [1.8, 0.1, 0.0])] {
        for _ in 0..50 {
            let axis = rng.int(0, 2);
            let sign = if rng.chance(0.5) { 1.0 } else { -1.0 };
            let mut p = [0.0f32; 3];
            for k in 0..3 {
                let v = if k == axis {
                    sign * b
                } else {
                    rng.range(-b, b)
                };
                p[k] = (t[k] + v) as f32;
            }
            pts.push(p);
        }
    }
    let d = decode(tensors(&g, &cpu()).0, tensors(&g, &cpu()).1, LATENT);
    let on = pc::loss(&field, &d.parts, d.exist.clone(), &pts, 1000.0).into_scalar::<f32>();
    assert!(on.abs() < 1e-8, "points on the surface: ℓ_pc = {on}");
    // 0.1 m off box 0's +Z face: d = 0.1 for that part, α ≈ 1 → 0.01 per point.
    let off: Vec<[f32; 3]> = (0..10).map(|k| [0.04 * k as f32 - 0.2, 0.0, 0.6]).collect();
    let v = pc::loss(&field, &d.parts, d.exist.clone(), &off, 1000.0).into_scalar::<f32>();
    assert!((v - 0.1).abs() < 1e-3, "10 points 0.1 m off: {v}");
    // Inside counts the same as outside (d² is signed-agnostic).
    let inside: Vec<[f32; 3]> = (0..10).map(|k| [0.04 * k as f32 - 0.2, 0.0, 0.4]).collect();
    let vi = pc::loss(&field, &d.parts, d.exist, &inside, 1000.0).into_scalar::<f32>();
    assert!((vi - 0.1).abs() < 1e-3, "10 points 0.1 m inside: {vi}");
}

/// A cabinet body (slot 0) and a door (slot 1) in front of it (front faces −X), hinged on a
/// vertical axis at the door's +Y edge; `inward` picks the axis sign that swings the door into
/// the body for positive angles.
fn cabinet(inward: bool, class: usize) -> GraphTensor {
    let mut g = GraphTensor::empty();
    set_part(&mut g, 0, 1.0, [0.5, 0.5, 0.5], [0.0, 0.0, 0.0]);
    set_part(&mut g, 1, 1.0, [0.02, 0.4, 0.45], [-0.55, 0.0, 0.0]);
    let dir = if inward {
        [0.0, 0.0, 1.0]
    } else {
        [0.0, 0.0, -1.0]
    };
    set_edge(
        &mut g,
        0,
        1,
        class,
        [-0.53, 0.4, 0.0],
        dir,
        [[0.0, 1.5], [0.0, 0.0]],
    );
    g
}

#[test]
fn mobility_loss_sees_a_door_sweeping_through_its_neighbour() {
    let field = BoxField { latent: LATENT };
    let inward = cabinet(true, 1);
    assert!(
        term(&field, &inward, Term::Pen, &cpu()).is_none(),
        "no overlap at rest"
    );
    let v = value(&field, &inward, Term::Mob);
    assert!(v > 0.0, "door swinging into the body: ℓ_mob = {v}");
    // The same door swinging outwards collides with nothing.
    assert_eq!(value(&field, &cabinet(false, 1), Term::Mob), 0.0);
    // Class 2 negates the line: the outward axis with class 2 is the inward motion.
    let neg = value(&field, &cabinet(false, 2), Term::Mob);
    assert!((neg - v).abs() < 1e-4 * v, "{neg} vs {v}");
    // Below the edge threshold nothing is swept; the weight scales with c̃.
    let mut weak = inward.clone();
    weak.edge_mut(edge_index(0, 1))[..3].copy_from_slice(&[0.95, 0.05, 0.0]);
    assert_eq!(value(&field, &weak, Term::Mob), 0.0);
    let mut half = inward;
    half.edge_mut(edge_index(0, 1))[..3].copy_from_slice(&[0.5, 0.5, 0.0]);
    let vh = value(&field, &half, Term::Mob);
    assert!((vh - 0.5 * v).abs() < 1e-4 * v, "{vh} vs {}", 0.5 * v);
}

#[test]
fn tensor_screw_transform_matches_kinematics() {
    let dev = cpu();
    let line = PluckerLine::through(&Point3::new(0.3, -0.2, 0.5), &Vector3::new(1.0, 2.0, 0.5));
    let (theta, d) = (0.7f64, 0.2f64);
    let want = screw_transform(&line, theta, d);
    let row = |v: &Vector3<f64>| {
        Tensor::<2>::from_data(
            TensorData::new(vec![v.x as f32, v.y as f32, v.z as f32], [1, 3]),
            &dev,
        )
    };
    let l = row(&line.l);
    let p0 = mob::cross(l.clone(), row(&line.m));
    let th = Tensor::<2>::from_data(TensorData::new(vec![theta as f32], [1, 1]), &dev);
    let r = mob::rotation(l.clone(), th);
    let tr = p0.clone() - mob::apply(r.clone(), p0) + l * d as f32;
    let x = Vector3::new(0.1, -0.4, 0.9);
    let got: Vec<f32> = (mob::apply(r.clone(), row(&x)) + tr.clone())
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let w = want * Point3::from(x);
    for k in 0..3 {
        assert!((got[k] as f64 - w[k]).abs() < 1e-5, "{got:?} vs {w}");
    }
    // Rᵀ undoes R.
    let back: Vec<f32> = mob::apply_transpose(r.clone(), mob::apply(r, row(&x)))
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    for k in 0..3 {
        assert!((back[k] as f64 - x[k]).abs() < 1e-5);
    }
}

/// A three-part graph where every term is active: overlapping boxes, a door edge, points.
fn busy() -> GraphTensor {
    let mut g = cabinet(true, 1);
    set_part(&mut g, 2, 0.8, [0.3, 0.3, 0.2], [0.3, 0.2, 0.6]);
    g.node_mut(0)[node_ch::EXIST] = 0.9;
    // Class probabilities strictly inside (0, 1), both chiralities over the threshold.
    g.edge_mut(edge_index(0, 1))[..3].copy_from_slice(&[0.2, 0.6, 0.2]);
    let mut rng = Rng::new(8);
    for i in 0..3 {
        for c in node_ch::LATENT + 3..node_ch::LATENT + LATENT {
            g.node_mut(i)[c] = rng.range(-0.5, 0.5) as f32;
        }
    }
    g
}

#[test]
fn gradients_match_finite_differences() {
    let field = mixed();
    let g = busy();
    let ad = cpu_autodiff();
    // (term, is_node, flat index, what)
    let picks: Vec<(Term, bool, usize, &str)> = {
        let n = |i: usize, c: usize| i * NODE_DIM + c;
        let e01 = edge_index(0, 1) * EDGE_DIM;
        let mut v = Vec::new();
        for t in [Term::Pc, Term::Pen, Term::Mob] {
            v.push((t, true, n(0, node_ch::BOX), "box"));
            v.push((t, true, n(2, node_ch::BOX + 2), "box"));
            v.push((t, true, n(1, node_ch::CENTER), "centre"));
            v.push((t, true, n(2, node_ch::CENTER + 2), "centre"));
            v.push((t, true, n(0, node_ch::LATENT + 5), "latent"));
            v.push((t, true, n(1, node_ch::LATENT + 1), "latent"));
        }
        v.push((Term::Pc, true, n(0, node_ch::EXIST), "existence"));
        v.push((Term::Pc, true, n(2, node_ch::EXIST), "existence"));
        v.push((Term::Pen, true, n(2, node_ch::EXIST), "existence"));
        v.push((Term::Pen, true, n(0, node_ch::EXIST), "existence"));
        v.push((Term::Mob, false, e01 + 1, "edge existence"));
        v.push((
            Term::Mob,
            false,
            e01 + edge_ch::REVOLUTE + 1,
            "revolute limit",
        ));
        v.push((Term::Mob, false, e01 + edge_ch::DIR, "axis"));
        v.push((Term::Mob, false, e01 + edge_ch::MOMENT + 2, "moment"));
        v
    };
    let mut checked = 0;
    for which in [Term::Pc, Term::Pen, Term::Mob] {
        let (n, e) = tensors(&g, &ad);
        let (n, e) = (n.require_grad(), e.require_grad());
        let loss = term_of(&field, n.clone(), e.clone(), which).expect("term active");
        let grads = loss.backward();
        let gn: Vec<f32> = n.grad(&grads).unwrap().into_data().try_to_vec().unwrap();
        let ge: Vec<f32> = e
            .grad(&grads)
            .map(|t| t.into_data().try_to_vec().unwrap())
            .unwrap_or_else(|| vec![0.0; NUM_EDGES * EDGE_DIM]);
        for &(t, node, k, what) in picks.iter().filter(|p| p.0 == which) {
            let f = |delta: f32| {
                let mut gg = g.clone();
                if node {
                    gg.nodes[k] += delta;
                } else {
                    gg.edges[k] += delta;
                }
                value(&field, &gg, t)
            };
            let h = 2e-3f32;
            let (p, z, m) = (f(h), f(0.0), f(-h));
            let fds = [
                (p - m) / (2.0 * h as f64),
                (p - z) / h as f64,
                (z - m) / h as f64,
            ];
            let ad = if node { gn[k] } else { ge[k] } as f64;
            let scale = z.abs().max(1e-3);
            let rel = fds
                .iter()
                .map(|fd| (fd - ad).abs() / (fd.abs() + 0.02 * scale))
                .fold(f64::INFINITY, f64::min);
            assert!(
                rel < 5e-2,
                "{t:?} d/d {what} [{k}]: autodiff {ad}, finite differences {fds:?} (loss {z})"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, picks.len());
}

#[test]
fn options_follow_the_paper_and_bad_values_name_field_limit_value() {
    let all = GuidanceOptions::paper(vec![[0.0; 3]], Terms::ALL);
    assert_eq!(
        (all.w_pc, all.w_pen, all.w_mob),
        (15.0, 2.0 / 3.0, 2.0 / 3.0)
    );
    let pc_pen = GuidanceOptions::paper(
        vec![[0.0; 3]],
        Terms {
            pc: true,
            pen: true,
            mob: false,
        },
    );
    assert_eq!((pc_pen.w_pc, pc_pen.w_pen, pc_pen.w_mob), (22.5, 1.0, 0.0));
    assert_eq!((all.steps, all.tau), (500, 1000.0));
    // physnap's defaults: the same terms with ℓ_pen and ℓ_mob at 3× the paper's weight.
    let ours = GuidanceOptions::defaults(vec![[0.0; 3]], Terms::ALL);
    assert_eq!((ours.w_pc, ours.w_pen, ours.w_mob), (15.0, 2.0, 2.0));
    assert_eq!(GuidanceOptions::default().w_pen, 2.0);
    assert_eq!(
        (ours.steps, ours.tau, ours.max_step),
        (500, 1000.0, Some(0.02))
    );
    assert!(all.validate(1000).is_ok());
    assert_eq!(all.refine_steps, 0, "the paper's settings do not refine");
    assert!((all.refine_max_step().unwrap() - 0.002).abs() < 1e-12);
    // Each bad field is refused with a message naming the field, the value and the limit.
    let cases: [(GuidanceOptions, &[&str]); 7] = [
        (
            GuidanceOptions {
                w_pen: -1.0,
                ..all.clone()
            },
            &["guidance.w_pen", "-1", "[0, "],
        ),
        (
            GuidanceOptions {
                steps: 1001,
                ..all.clone()
            },
            &["guidance.steps", "1001", "1000"],
        ),
        (
            GuidanceOptions {
                points: vec![],
                ..all.clone()
            },
            &["guidance.points", "0 points"],
        ),
        (
            GuidanceOptions {
                points: vec![[0.0, f32::NAN, 0.0]],
                ..all.clone()
            },
            &["guidance.points[0]", "finite"],
        ),
        (
            GuidanceOptions {
                refine_steps: 1001,
                ..all.clone()
            },
            &["guidance.refine_steps", "1001", "at most 1000"],
        ),
        (
            GuidanceOptions {
                refine_physics_steps: 1001,
                ..all.clone()
            },
            &["guidance.refine_physics_steps", "1001", "at most 1000"],
        ),
        (
            GuidanceOptions { tau: 0.0, ..all },
            &["guidance.tau", "(0, 1e9]"],
        ),
    ];
    for (bad, want) in cases {
        let e = bad.validate(1000).unwrap_err().to_string();
        assert!(
            want.iter().all(|w| e.contains(w)),
            "{e} should name {want:?}"
        );
    }
}

#[test]
fn overlap_energy_equals_the_sum_over_every_point_in_value_and_gradient() {
    use super::field::{PartTensors, overlap_energy, part_sdf};
    let field = mixed();
    let ad = cpu_autodiff();
    let mut rng = Rng::new(5);
    let mut draw = |n: usize, lo: f64, hi: f64| -> Vec<f32> {
        (0..n).map(|_| rng.range(lo, hi) as f32).collect()
    };
    // 3 parts; 200 points, each seen from part i and part j: some overlap, most do not.
    let (k, nq) = (3, 200);
    let data = [
        draw(k * 3, 0.2, 0.5),
        draw(k * 3, -0.2, 0.2),
        draw(k * LATENT, 0.1, 0.6),
        draw(2 * nq * 3, -0.8, 0.8),
        draw(nq, 0.5, 2.0),
    ];
    let pairs: Vec<i64> = (0..nq).map(|a| (a % k) as i64).collect();
    let others: Vec<i64> = (0..nq).map(|a| ((a + 1) % k) as i64).collect();
    let idx_data = [pairs, others].concat();
    // Value and gradient (boxes, centres, codes) of the energy, on a fresh graph each time.
    let run = |pruned: bool| -> (f32, Vec<f32>) {
        let t2 = |v: &Vec<f32>, c: usize| {
            Tensor::<2>::from_data(TensorData::new(v.clone(), [v.len() / c, c]), &ad)
        };
        let boxes = t2(&data[0], 3).require_grad();
        let centres = t2(&data[1], 3).require_grad();
        let codes = t2(&data[2], LATENT).require_grad();
        let idx = Tensor::<1, Int>::from_data(TensorData::new(idx_data.clone(), [2 * nq]), &ad);
        let w = Tensor::<1>::from_data(TensorData::new(data[4].clone(), [nq]), &ad);
        let parts = PartTensors::new(boxes.clone(), centres.clone(), codes.clone());
        let u = t2(&data[3], 3) + centres.clone().select(0, idx.clone());
        let l = if pruned {
            let idx: Vec<usize> = idx_data.iter().map(|&i| i as usize).collect();
            overlap_energy(&field, &parts, &idx, u, w).expect("some points overlap")
        } else {
            let d = part_sdf(&field, &parts, idx, u);
            (super::grid::psi(d.clone().narrow(0, 0, nq), d.narrow(0, nq, nq)) * w).sum()
        };
        let value = l.clone().into_data().try_to_vec::<f32>().unwrap()[0];
        let g = l.backward();
        let flat =
            |t: &Tensor<2>| -> Vec<f32> { t.grad(&g).unwrap().into_data().try_to_vec().unwrap() };
        (value, [flat(&boxes), flat(&centres), flat(&codes)].concat())
    };
    let (va, ga) = run(false);
    let (vp, gp) = run(true);
    assert!(va > 0.0);
    assert!((va - vp).abs() <= 1e-5 * va.abs(), "{va} vs {vp}");
    for (a, p) in ga.iter().zip(&gp) {
        assert!((a - p).abs() <= 1e-4 * a.abs().max(1e-3), "{a} vs {p}");
    }
}

#[test]
fn pruned_point_cloud_loss_equals_the_dense_one_in_value_and_gradient() {
    let field = mixed();
    let ad = cpu_autodiff();
    let mut rng = Rng::new(21);
    let pts: Vec<[f32; 3]> = (0..300)
        .map(|_| std::array::from_fn(|_| rng.range(-0.8, 1.0) as f32))
        .collect();
    // õ = 0 everywhere (an early, untrained x̂₀): logits of −10⁹·d², where the softmax shift
    // must come from the differentiable pass itself.
    let mut ghost = busy();
    for i in 0..K {
        ghost.node_mut(i)[node_ch::EXIST] = 0.0;
    }
    for (g, tau) in [(&busy(), 1000.0f32), (&busy(), 10.0), (&ghost, 1000.0)] {
        let run = |pruned: bool| -> (f32, Vec<f32>) {
            let (n, e) = tensors(g, &ad);
            let n = n.require_grad();
            let d = decode(n.clone(), e, field.latent());
            let l = if pruned {
                pc::loss(&field, &d.parts, d.exist.clone(), &pts, tau)
            } else {
                pc::loss_dense(&field, &d.parts, d.exist.clone(), &pts, tau)
            };
            let value = l.clone().into_scalar::<f32>();
            let grads = l.backward();
            let gn: Vec<f32> = n.grad(&grads).unwrap().into_data().try_to_vec().unwrap();
            (value, gn)
        };
        let (vd, gd) = run(false);
        let (vp, gp) = run(true);
        assert!(vd > 0.0);
        assert!((vd - vp).abs() <= 1e-5 * vd, "τ {tau}: {vd} vs {vp}");
        let scale = gd.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(scale > 0.0);
        for (k, (a, p)) in gd.iter().zip(&gp).enumerate() {
            assert!(
                (a - p).abs() <= 1e-4 * scale,
                "τ {tau}, node channel {k}: {a} vs {p}"
            );
        }
    }
}

/// The value-only part SDF (what every first pass selects points with) equals the
/// differentiable one, for the analytic field (default `sdf_values`) and for the learned decoder
/// behind `LatentSdfDecoder` (the `HostDecoder` path), inside and outside the boxes.
#[test]
fn value_only_part_sdf_equals_the_differentiable_one() {
    use super::field::{part_sdf, part_sdf_values};
    use crate::model::shape_prior::LatentSdfDecoder;
    let cfg = ShapePriorConfig {
        latent: LATENT,
        decoder_hidden: 32,
        decoder_blocks: 2,
        encoder_hidden: 8,
        encoder_blocks: 1,
        pe_freqs: 4,
        code_every_block: false,
    };
    let mut rng = Rng::new(21);
    let learned = LatentSdfDecoder::new(&crate::model::shape_prior::tests::randomised(
        ShapeDecoder::new(&cfg, &mut rng, &cpu()),
        5,
    ));
    let boxed = BoxField { latent: LATENT };
    let dev = cpu_autodiff();
    let (k, q) = (4, 500);
    let mut draw = |n: usize, lo: f64, hi: f64| -> Vec<f32> {
        (0..n).map(|_| rng.range(lo, hi) as f32).collect()
    };
    let t2 = |v: Vec<f32>, c: usize| {
        Tensor::<2>::from_data(TensorData::new(v.clone(), [v.len() / c, c]), &dev)
    };
    let parts = PartTensors::new(
        t2(draw(k * 3, 0.05, 0.4), 3),
        t2(draw(k * 3, -0.3, 0.3), 3),
        t2(draw(k * LATENT, -0.6, 0.6), LATENT),
    );
    let u = draw(q * 3, -0.7, 0.7);
    let idx: Vec<usize> = (0..q).map(|a| a % k).collect();
    let values = parts.values().expect("f32 tensors");
    for field in [&learned as &dyn SdfField, &boxed] {
        let want: Vec<f32> = part_sdf(
            field,
            &parts,
            grid::index_tensor(&idx, &dev),
            t2(u.clone(), 3),
        )
        .into_data()
        .try_to_vec()
        .unwrap();
        let pts: Vec<[f32; 3]> = u.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        let got = part_sdf_values(field, &values, &idx, &pts);
        assert_eq!(got.len(), q);
        let (inside, outside) =
            want.iter().fold(
                (0, 0),
                |(i, o), &d| {
                    if d < 0.0 { (i + 1, o) } else { (i, o + 1) }
                },
            );
        assert!(
            inside > 0 && outside > 0,
            "{inside} inside, {outside} outside"
        );
        for (a, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                (g - w).abs() <= 1e-5 * w.abs().max(1.0),
                "point {a}: {g} vs {w}"
            );
        }
    }
}

/// The learned field's differentiable SDF (host decoder + first-order surrogate) has the burn
/// decoder's value and the gradients that burn's autodiff takes through every decoder layer,
/// with respect to the points and the codes, under a non-uniform upstream gradient.
#[test]
fn host_decoder_gradients_equal_burn_autodiff() {
    use crate::model::shape_prior::LatentSdfDecoder;
    use crate::model::shape_prior::tests::randomised;
    for (seed, pe_freqs, blocks, code_every_block) in [
        (31, 4, 2, false),
        (32, 0, 1, false),
        (33, 8, 0, false),
        (34, 4, 3, true),
    ] {
        let cfg = ShapePriorConfig {
            latent: LATENT,
            decoder_hidden: 32,
            decoder_blocks: blocks,
            encoder_hidden: 8,
            encoder_blocks: 1,
            pe_freqs,
            code_every_block,
        };
        let mut rng = Rng::new(seed);
        let learned =
            LatentSdfDecoder::new(&randomised(ShapeDecoder::new(&cfg, &mut rng, &cpu()), 7));
        let dev = cpu_autodiff();
        let (p, n) = (3, 700); // several 128-row blocks and a partial one
        let mut draw = |len: usize, lo: f64, hi: f64| -> Vec<f32> {
            (0..len).map(|_| rng.range(lo, hi) as f32).collect()
        };
        let (q, codes, w) = (
            draw(n * 3, -0.6, 0.6),
            draw(p * LATENT, -1.0, 1.0),
            draw(n, 0.5, 2.0),
        );
        let idx: Vec<usize> = (0..n).map(|a| (a * 7 + a / 5) % p).collect();
        let run = |field: &dyn SdfField| -> [Vec<f32>; 3] {
            let t2 = |v: &Vec<f32>, c: usize| {
                Tensor::<2>::from_data(TensorData::new(v.clone(), [v.len() / c, c]), &dev)
            };
            let (qt, ct) = (t2(&q, 3).require_grad(), t2(&codes, LATENT).require_grad());
            let s = field.sdf(qt.clone(), ct.clone(), grid::index_tensor(&idx, &dev));
            let wt = Tensor::<1>::from_data(TensorData::new(w.clone(), [n]), &dev);
            let g = (s.clone().powi_scalar(2) * wt).sum().backward();
            let flat = |t: &Tensor<2>| -> Vec<f32> {
                t.grad(&g).unwrap().into_data().try_to_vec().unwrap()
            };
            [s.into_data().try_to_vec().unwrap(), flat(&qt), flat(&ct)]
        };
        let host = run(&learned);
        let burn = run(learned.decoder());
        for (name, (h, b)) in ["value", "∂/∂q", "∂/∂z"].iter().zip(host.iter().zip(&burn)) {
            assert_eq!(h.len(), b.len());
            let scale = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            assert!(scale > 0.0, "{name}: all zero");
            for (a, (x, y)) in h.iter().zip(b).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-4 * scale,
                    "{cfg:?} {name}[{a}]: host {x} vs burn {y}"
                );
            }
        }
    }
}

/// A wall of scan points on x = 1 seen from a camera at x = −2, and a box part between them.
fn carving_setup(part_x: f32) -> (GraphTensor, Vec<[f32; 3]>, [f32; 3]) {
    let wall: Vec<[f32; 3]> = (0..12)
        .flat_map(|i| (0..12).map(move |j| [1.0, -0.55 + 0.1 * i as f32, -0.55 + 0.1 * j as f32]))
        .collect();
    let mut g = GraphTensor::empty();
    set_part(&mut g, 0, 1.0, [0.1, 0.6, 0.6], [1.1, 0.0, 0.0]);
    set_part(&mut g, 1, 1.0, [0.2, 0.2, 0.2], [part_x, 0.0, 0.0]);
    (g, wall, [-2.0, 0.0, 0.0])
}

fn free_loss(
    g: &GraphTensor,
    pts: &[[f32; 3]],
    cam: [f32; 3],
    dev: &burn::tensor::Device,
) -> Option<Tensor<1>> {
    let (n, e) = tensors(g, dev);
    free_loss_of(n, e, pts, cam)
}

/// ℓ_free of nodes and edges on any device, seen from `cam`.
fn free_loss_of(n: Tensor<2>, e: Tensor<2>, pts: &[[f32; 3]], cam: [f32; 3]) -> Option<Tensor<1>> {
    let field = BoxField { latent: LATENT };
    let d = decode(n, e, LATENT);
    let fs = crate::engine::free_space::FreeSpace::new(pts, &[cam]);
    free::loss(
        &field,
        &d.parts,
        d.exist.clone(),
        &d.host,
        &fs.samples(),
        pts.len(),
        0.5 * fs.margin(),
    )
}

#[test]
fn free_space_loss_carves_a_part_between_the_camera_and_the_points() {
    // In front of the wall (in the camera's free space): penalised; the wall part behind its
    // own points is not.
    let (g, pts, cam) = carving_setup(0.0);
    let v = free_loss(&g, &pts, cam, &cpu()).map(|t| t.into_scalar::<f32>());
    assert!(v.is_some_and(|v| v > 0.0), "{v:?}");
    let (g, pts, cam) = carving_setup(-3.0);
    assert!(
        free_loss(&g, &pts, cam, &cpu()).is_none(),
        "behind the camera: no free space there"
    );
    // Descending the loss moves the part out of the free space, shrinks it or fades it.
    let (mut g, pts, cam) = carving_setup(0.0);
    let first = free_loss(&g, &pts, cam, &cpu())
        .unwrap()
        .into_scalar::<f32>();
    let dev = cpu_autodiff();
    for _ in 0..40 {
        let (n, e) = tensors(&g, &dev);
        let n = n.require_grad();
        let Some(l) = free_loss_of(n.clone(), e, &pts, cam) else {
            break;
        };
        let grads = l.backward();
        let gn: Vec<f32> = n.grad(&grads).unwrap().into_data().try_to_vec().unwrap();
        for (x, dx) in g.nodes.iter_mut().zip(gn) {
            *x -= (dx * 0.05).clamp(-0.02, 0.02);
        }
    }
    let last = free_loss(&g, &pts, cam, &cpu()).map_or(0.0, |t| t.into_scalar::<f32>());
    assert!(last < 0.2 * first, "ℓ_free {first} → {last}");
}

#[test]
fn bad_cameras_name_field_limit_value() {
    let pts = vec![[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]];
    let base = GuidanceOptions::defaults(pts, Terms::ALL);
    let ok = base.clone().with_cameras(vec![[-1.0, 0.5, 0.5]], None);
    assert!(ok.validate(1000).is_ok());
    assert_eq!(ok.w_free, DEFAULT_W_FREE);
    assert_eq!(base.clone().with_cameras(Vec::new(), Some(3.0)).w_free, 0.0);
    let msg = |o: GuidanceOptions| o.validate(1000).unwrap_err().to_string();
    let inside = msg(base.clone().with_cameras(vec![[0.5, 0.5, 0.5]], None));
    assert!(
        inside.contains("guidance.cameras[0]") && inside.contains("outside the points' box"),
        "{inside}"
    );
    let nan = msg(base.clone().with_cameras(vec![[-1.0, f32::NAN, 0.0]], None));
    assert!(
        nan.contains("guidance.cameras[0]") && nan.contains("finite"),
        "{nan}"
    );
    let many = msg(base.clone().with_cameras(vec![[-1.0, 0.0, 0.0]; 17], None));
    assert!(
        many.contains("guidance.cameras") && many.contains("at most 16") && many.contains("17"),
        "{many}"
    );
    let w = msg(base.with_cameras(vec![[-1.0, 0.0, 0.0]], Some(-2.0)));
    assert!(w.contains("guidance.w_free") && w.contains("-2"), "{w}");
}
