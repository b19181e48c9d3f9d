//! Tests of `denoiser`.

use super::*;
use crate::graph::{GraphTensor, edge_ch};
use crate::model::{cpu, cpu_autodiff};

fn tiny(categories: usize) -> DenoiserConfig {
    DenoiserConfig {
        width: 32,
        layers: 2,
        head_channels: 8,
        t_pe_dim: 16,
        slot_pe_dim: 8,
        node_head_hidden: vec![16, 16],
        edge_head_hidden: vec![16, 8],
        categories,
        legacy_edge_embedding: false,
        category_layers: false,
    }
}

fn gaussian(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.gauss() as f32).collect()
}

/// B random graphs (flat node and edge values).
fn random_inputs(seed: u64, b: usize) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Rng::new(seed);
    (
        gaussian(&mut rng, b * K * NODE_DIM),
        gaussian(&mut rng, b * NUM_EDGES * EDGE_DIM),
    )
}

fn tensors(v: &[f32], e: &[f32], device: &Device) -> (Tensor<3>, Tensor<3>) {
    let b = v.len() / (K * NODE_DIM);
    (
        Tensor::from_data(TensorData::new(v.to_vec(), [b, K, NODE_DIM]), device),
        Tensor::from_data(
            TensorData::new(e.to_vec(), [b, NUM_EDGES, EDGE_DIM]),
            device,
        ),
    )
}

fn ints(v: &[i64], device: &Device) -> Tensor<1, Int> {
    int_tensor(v.to_vec(), device)
}

fn vec_of(x: Tensor<3>) -> Vec<f32> {
    x.try_into_vec_as::<f32>().expect("f32")
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// Run the model on flat inputs, return flat outputs.
fn run(m: &Denoiser, v: &[f32], e: &[f32], t: &[i64], c: Option<&[i64]>) -> (Vec<f32>, Vec<f32>) {
    let device = cpu();
    let (vt, et) = tensors(v, e, &device);
    let (ev, ee) = m.forward(vt, et, ints(t, &device), c.map(|c| ints(c, &device)));
    (vec_of(ev), vec_of(ee))
}

#[test]
fn nap_parameter_count_matches_spec() {
    let device = cpu();
    let m = Denoiser::new(&DenoiserConfig::nap(), &device).unwrap();
    assert_eq!(m.parameter_count(), 20_753_380);
    // With categories: a (46 + 1) × 512 table (the extra row is "no category").
    let cfg = DenoiserConfig {
        categories: 46,
        ..DenoiserConfig::nap()
    };
    let m = Denoiser::new(&cfg, &device).unwrap();
    assert_eq!(m.parameter_count(), 20_753_380 + 47 * 512);
    // The default CPU model (documented on `Default`).
    let m = Denoiser::new(&DenoiserConfig::default(), &device).unwrap();
    assert_eq!(m.parameter_count(), 2_161_508);
    assert_eq!(m.config().categories, 46);
    // The legacy embedding has the same shapes.
    let cfg = DenoiserConfig {
        legacy_edge_embedding: true,
        ..DenoiserConfig::nap()
    };
    assert_eq!(
        Denoiser::new(&cfg, &device).unwrap().parameter_count(),
        20_753_380
    );
}

#[test]
fn model_can_be_shared_across_threads() {
    fn shareable<T: Send + Sync + 'static>() {}
    shareable::<Denoiser>();
    shareable::<DenoiserConfig>();
}

#[test]
fn config_validation_names_field() {
    assert!(DenoiserConfig::default().validate().is_ok());
    assert!(DenoiserConfig::nap().validate().is_ok());
    let bad = DenoiserConfig {
        head_channels: 30,
        ..DenoiserConfig::nap()
    };
    let msg = bad.validate().unwrap_err().to_string();
    assert!(msg.contains("head_channels") && msg.contains("30"), "{msg}");
    let bad = DenoiserConfig {
        t_pe_dim: 7,
        ..DenoiserConfig::nap()
    };
    let msg = Denoiser::new(&bad, &cpu()).unwrap_err().to_string();
    assert!(msg.contains("t_pe_dim") && msg.contains('7'), "{msg}");
    let bad = DenoiserConfig {
        node_head_hidden: vec![8, 0],
        ..DenoiserConfig::nap()
    };
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("node_head_hidden")
    );
}

#[test]
fn sinusoidal_table_matches_formula_and_slots_are_distinct() {
    let d = 100;
    let pe = sinusoidal_table(K, d);
    // Row 0: sin 0 = 0, cos 0 = 1.
    assert!(pe[..d].chunks(2).all(|p| p[0] == 0.0 && p[1] == 1.0));
    // Exponent 4k/d: k = 1 at n = 3 → sin(3 · 10000^(−0.04)).
    let want = (3.0f64 * 10000f64.powf(-0.04)).sin() as f32;
    assert!((pe[3 * d + 2] - want).abs() < 1e-6);
    for i in 0..K {
        for j in 0..i {
            let diff = max_abs_diff(&pe[i * d..(i + 1) * d], &pe[j * d..(j + 1) * d]);
            assert!(diff > 1e-3, "slot PE rows {i} and {j} coincide");
        }
    }
}

#[test]
fn shapes_and_determinism() {
    let device = cpu();
    let m = Denoiser::new(&tiny(0), &device).unwrap();
    let (v, e) = random_inputs(1, 3);
    let (vt, et) = tensors(&v, &e, &device);
    let t = ints(&[0, 500, 999], &device);
    m.check_inputs(&vt, &et, &t, None).unwrap();
    let (ev, ee) = m.forward(vt, et, t, None);
    assert_eq!(ev.dims(), [3, K, NODE_DIM]);
    assert_eq!(ee.dims(), [3, NUM_EDGES, EDGE_DIM]);
    let a = run(&m, &v, &e, &[0, 500, 999], None);
    let b = run(&m, &v, &e, &[0, 500, 999], None);
    assert_eq!(a, b);
    assert!(a.0.iter().chain(&a.1).all(|x| x.is_finite()));
    // Batch entries are independent: sample 1 alone gives the same numbers.
    let one = run(
        &m,
        &v[K * NODE_DIM..2 * K * NODE_DIM],
        &e[NUM_EDGES * EDGE_DIM..2 * NUM_EDGES * EDGE_DIM],
        &[500],
        None,
    );
    assert!(max_abs_diff(&one.0, &a.0[K * NODE_DIM..2 * K * NODE_DIM]) < 1e-5);
    assert!(max_abs_diff(&one.1, &a.1[NUM_EDGES * EDGE_DIM..2 * NUM_EDGES * EDGE_DIM]) < 1e-5);
}

#[test]
fn check_inputs_reports_bad_values() {
    let device = cpu();
    let m = Denoiser::new(&tiny(4), &device).unwrap();
    let (v, e) = random_inputs(2, 1);
    let (vt, et) = tensors(&v, &e, &device);
    let err = m
        .check_inputs(&vt, &et, &ints(&[1000], &device), None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("t[0]") && err.contains("1000") && err.contains("999"),
        "{err}"
    );
    let c = ints(&[5], &device);
    let err = m
        .check_inputs(&vt, &et, &ints(&[3], &device), Some(&c))
        .unwrap_err()
        .to_string();
    assert!(err.contains("category[0]") && err.contains('5'), "{err}");
    let c = ints(&[4], &device); // the "no category" row is valid
    m.check_inputs(&vt, &et, &ints(&[3], &device), Some(&c))
        .unwrap();
    let bad_e = et.clone().narrow(1, 0, 27);
    let err = m
        .check_inputs(&vt, &bad_e, &ints(&[3], &device), None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("[1, 28, 13]"), "{err}");
    let m0 = Denoiser::new(&tiny(0), &device).unwrap();
    assert!(
        m0.check_inputs(&vt, &et, &ints(&[3], &device), Some(&c))
            .is_err()
    );
}

#[test]
fn slot_encoding_breaks_permutation_equivariance() {
    let m = Denoiser::new(&tiny(0), &cpu()).unwrap();
    let (v, e) = random_inputs(3, 1);
    let g = GraphTensor {
        nodes: v.clone(),
        edges: e.clone(),
    };
    let mut perm = [0, 1, 2, 3, 4, 5, 6, 7];
    perm.swap(1, 5);
    let gp = g.permuted(&perm).unwrap();
    let (ov, oe) = run(&m, &v, &e, &[400], None);
    let (pv, pe) = run(&m, &gp.nodes, &gp.edges, &[400], None);
    // Permute the original output the same way (with the class-1/2 swap of flipped pairs).
    let op = GraphTensor {
        nodes: ov.clone(),
        edges: oe.clone(),
    }
    .permuted(&perm)
    .unwrap();
    let dv = max_abs_diff(&op.nodes, &pv);
    let de = max_abs_diff(&op.edges, &pe);
    assert!(dv > 1e-3 && de > 1e-3, "output is equivariant: {dv} {de}");
    // Sanity: the swap really moved data (the inputs differ).
    assert!(max_abs_diff(&gp.nodes, &v) > 0.1);
}

#[test]
fn time_encoding_changes_output() {
    let m = Denoiser::new(&tiny(0), &cpu()).unwrap();
    let (v, e) = random_inputs(4, 1);
    let a = run(&m, &v, &e, &[10], None);
    let b = run(&m, &v, &e, &[11], None);
    let c = run(&m, &v, &e, &[900], None);
    assert!(max_abs_diff(&a.0, &b.0) > 1e-5 && max_abs_diff(&a.1, &b.1) > 1e-5);
    assert!(max_abs_diff(&a.0, &c.0) > 1e-3 && max_abs_diff(&a.1, &c.1) > 1e-3);
}

#[test]
fn category_conditions_output() {
    let m = Denoiser::new(&tiny(5), &cpu()).unwrap();
    let (v, e) = random_inputs(5, 2);
    let a = run(&m, &v, &e, &[300, 300], Some(&[0, 0]));
    let b = run(&m, &v, &e, &[300, 300], Some(&[3, 3]));
    let none = run(&m, &v, &e, &[300, 300], None);
    let explicit_none = run(&m, &v, &e, &[300, 300], Some(&[5, 5]));
    assert!(max_abs_diff(&a.0, &b.0) > 1e-3 && max_abs_diff(&a.1, &b.1) > 1e-3);
    assert!(max_abs_diff(&a.0, &none.0) > 1e-3);
    assert_eq!(none, explicit_none, "None = the 'no category' row");
    // Per-sample categories: a batch with [0, 3] matches the two single-category runs.
    let mixed = run(&m, &v, &e, &[300, 300], Some(&[0, 3]));
    let half = K * NODE_DIM;
    assert!(max_abs_diff(&mixed.0[..half], &a.0[..half]) < 1e-5);
    assert!(max_abs_diff(&mixed.0[half..], &b.0[half..]) < 1e-5);

    // Unconditional: the argument is ignored.
    let m0 = Denoiser::new(&tiny(0), &cpu()).unwrap();
    let x = run(&m0, &v, &e, &[300, 300], None);
    let y = run(&m0, &v, &e, &[300, 300], Some(&[3, 3]));
    assert_eq!(x, y);
}

/// Perturb only the Plücker direction l of edge row `row`.
fn perturb_l(e: &[f32], row: usize) -> Vec<f32> {
    let mut p = e.to_vec();
    for a in 0..3 {
        p[row * EDGE_DIM + edge_ch::DIR + a] += 0.7 * (a as f32 + 1.0);
    }
    p
}

#[test]
fn fixed_edge_embedding_sees_plucker_direction() {
    let device = cpu();
    let m = Denoiser::new(&tiny(0), &device).unwrap();
    let (v, e) = random_inputs(6, 1);
    let row = edge_index(2, 6);
    let ep = perturb_l(&e, row);
    let (_, et) = tensors(&v, &e, &device);
    let (_, ept) = tensors(&v, &ep, &device);
    let g = vec_of(m.edge_embedding(et, None));
    let gp = vec_of(m.edge_embedding(ept, None));
    let w = m.config().width;
    // Both directed entries (2,6) and (6,2) change, nothing else.
    for entry in 0..DIRECTED {
        let d = max_abs_diff(
            &g[entry * w..(entry + 1) * w],
            &gp[entry * w..(entry + 1) * w],
        );
        if entry == 2 * K + 6 || entry == 6 * K + 2 {
            assert!(d > 1e-3, "entry {entry} unchanged");
        } else {
            assert_eq!(d, 0.0, "entry {entry} changed");
        }
    }
    let (ov, oe) = run(&m, &v, &e, &[200], None);
    let (pv, pe) = run(&m, &v, &ep, &[200], None);
    assert!(max_abs_diff(&ov, &pv) > 1e-6, "ε̂_V ignores l");
    // Other edges' outputs change too (through the graph layers).
    let other = edge_index(0, 1);
    assert!(
        max_abs_diff(
            &oe[other * EDGE_DIM..(other + 1) * EDGE_DIM],
            &pe[other * EDGE_DIM..(other + 1) * EDGE_DIM]
        ) > 1e-7
    );
}

#[test]
fn legacy_edge_embedding_ignores_plucker_direction() {
    let device = cpu();
    let cfg = DenoiserConfig {
        legacy_edge_embedding: true,
        ..tiny(0)
    };
    let m = Denoiser::new(&cfg, &device).unwrap();
    let (v, e) = random_inputs(7, 1);
    let row = edge_index(2, 6);
    let mut ep = perturb_l(&e, row);
    ep[row * EDGE_DIM + edge_ch::PRISMATIC + 1] += 1.3; // p_hi is unseen too
    let (_, et) = tensors(&v, &e, &device);
    let (_, ept) = tensors(&v, &ep, &device);
    assert_eq!(
        vec_of(m.edge_embedding(et.clone(), None)),
        vec_of(m.edge_embedding(ept, None))
    );
    // The moment m is seen.
    let mut em = e.clone();
    em[row * EDGE_DIM + edge_ch::MOMENT] += 0.5;
    let (_, emt) = tensors(&v, &em, &device);
    assert!(
        max_abs_diff(
            &vec_of(m.edge_embedding(et, None)),
            &vec_of(m.edge_embedding(emt, None))
        ) > 1e-4
    );
    // Through the whole network only the heads' skip input sees l and p_hi: ε̂_V and every
    // other edge row are bit-identical; only the Plücker and range outputs of that row move.
    let (ov, oe) = run(&m, &v, &e, &[200], None);
    let (pv, pe) = run(&m, &v, &ep, &[200], None);
    assert_eq!(ov, pv);
    for r in 0..NUM_EDGES {
        let (a, b) = (
            &oe[r * EDGE_DIM..(r + 1) * EDGE_DIM],
            &pe[r * EDGE_DIM..(r + 1) * EDGE_DIM],
        );
        if r == row {
            assert_eq!(a[..3], b[..3], "class head moved");
            assert!(max_abs_diff(&a[3..], &b[3..]) > 1e-5);
        } else {
            assert_eq!(a, b, "edge row {r} moved");
        }
    }
}

#[test]
fn reverse_direction_swaps_classes() {
    // Dense entry (j, i) of a pair i < j carries (c₀, c₂, c₁): a class-1 pair embeds at (i, j)
    // exactly like a class-2 pair at (j, i), and vice versa.
    let device = cpu();
    let m = Denoiser::new(&tiny(0), &device).unwrap();
    let mut g1 = GraphTensor::empty();
    let row = edge_index(1, 4);
    g1.edge_mut(row)[..3].copy_from_slice(&[0.0, 1.0, 0.0]);
    let mut g2 = GraphTensor::empty();
    g2.edge_mut(row)[..3].copy_from_slice(&[0.0, 0.0, 1.0]);
    let emb = |g: &GraphTensor| {
        let (_, et) = tensors(&g.nodes, &g.edges, &device);
        vec_of(m.edge_embedding(et, None))
    };
    let (a, b) = (emb(&g1), emb(&g2));
    let w = m.config().width;
    let at = |x: &[f32], i: usize, j: usize| x[(i * K + j) * w..(i * K + j + 1) * w].to_vec();
    assert_eq!(at(&a, 1, 4), at(&b, 4, 1));
    assert_eq!(at(&a, 4, 1), at(&b, 1, 4));
    assert!(max_abs_diff(&at(&a, 1, 4), &at(&a, 4, 1)) > 1e-4);
    // The diagonal carries all-zero inputs: only the biases.
    assert_eq!(at(&a, 3, 3), at(&b, 3, 3));
    assert_eq!(at(&a, 0, 0), at(&a, 7, 7));
}

/// y = x W + b with the weights read back from the module.
fn ref_linear(l: &Linear, x: &[f32]) -> Vec<f32> {
    let [d_in, d_out] = l.weight.val().dims();
    assert_eq!(x.len(), d_in);
    let w: Vec<f32> = l.weight.val().try_into_vec_as().unwrap();
    let mut y: Vec<f32> = match &l.bias {
        Some(b) => b.val().try_into_vec_as().unwrap(),
        None => vec![0.0; d_out],
    };
    for (i, xi) in x.iter().enumerate() {
        for (o, yo) in y.iter_mut().enumerate() {
            *yo += xi * w[i * d_out + o];
        }
    }
    y
}

fn ref_silu(x: Vec<f32>) -> Vec<f32> {
    x.into_iter().map(|v| v / (1.0 + (-v).exp())).collect()
}

fn ref_mlp(m: &WideMlp, z: Vec<f32>) -> Vec<f32> {
    let mut all = z.clone();
    let mut h = z;
    for l in &m.hidden {
        h = ref_linear(l, &h)
            .into_iter()
            .map(|v| if v >= 0.0 { v } else { 0.01 * v })
            .collect();
        all.extend_from_slice(&h);
    }
    ref_linear(&m.out, &all)
}

fn cat_all(parts: &[&[f32]]) -> Vec<f32> {
    parts.iter().flat_map(|p| p.iter().copied()).collect()
}

/// A literal, loop-by-loop transcription of method.md §3.1–§3.5 for one sample (no
/// factorisation, explicit concatenations), to check the batched implementation against.
fn reference_forward(
    m: &Denoiser,
    v: &[f32],
    e: &[f32],
    t: usize,
    category: Option<usize>,
) -> (Vec<f32>, Vec<f32>) {
    let cfg = m.config();
    let w = cfg.width;
    let cat: Option<Vec<f32>> = m.category.as_ref().map(|table| {
        let all: Vec<f32> = table.weight.val().try_into_vec_as().unwrap();
        let c = category.unwrap_or(cfg.categories);
        all[c * w..(c + 1) * w].to_vec()
    });
    let add_cat = |mut x: Vec<f32>| {
        if let Some(c) = &cat {
            x.iter_mut().zip(c).for_each(|(a, b)| *a += b);
        }
        x
    };
    let node = |i: usize| &v[i * NODE_DIM..(i + 1) * NODE_DIM];
    // §3.3 node embedding.
    let h0: Vec<Vec<f32>> = (0..K)
        .map(|i| {
            let mut h = vec![0.0; w];
            for (&(o, n), l) in NODE_SLICES.iter().zip(&m.node_embed) {
                let y = ref_linear(l, &node(i)[o..o + n]);
                h.iter_mut().zip(y).for_each(|(a, b)| *a += b);
            }
            add_cat(h)
        })
        .collect();
    // §3.1 directional / symmetric split, dense 8×8.
    let mut dm = vec![vec![0.0f32; 3]; K * K];
    let mut sym = vec![vec![0.0f32; 10]; K * K];
    for (idx, &(i, j)) in EDGE_PAIRS.iter().enumerate() {
        let row = &e[idx * EDGE_DIM..(idx + 1) * EDGE_DIM];
        dm[i * K + j] = row[..3].to_vec();
        dm[j * K + i] = vec![row[0], row[2], row[1]];
        sym[i * K + j] = row[3..].to_vec();
        sym[j * K + i] = row[3..].to_vec();
    }
    let g0: Vec<Vec<f32>> = (0..K * K)
        .map(|ij| {
            let s = &sym[ij];
            let (line, range) = if cfg.legacy_edge_embedding {
                (&s[3..9], &s[3..7])
            } else {
                (&s[0..6], &s[6..10])
            };
            let mut g = ref_linear(&m.edge_embed_class, &dm[ij]);
            for y in [
                ref_linear(&m.edge_embed_line, line),
                ref_linear(&m.edge_embed_range, range),
            ] {
                g.iter_mut().zip(y).for_each(|(a, b)| *a += b);
            }
            add_cat(g)
        })
        .collect();
    // §3.2 encodings.
    let tau = sinusoidal_table(TIME_STEPS, cfg.t_pe_dim)[t * cfg.t_pe_dim..(t + 1) * cfg.t_pe_dim]
        .to_vec();
    let slot = sinusoidal_table(K, cfg.slot_pe_dim);
    let pi = |i: usize| &slot[i * cfg.slot_pe_dim..(i + 1) * cfg.slot_pe_dim];
    // §3.4 graph layers (with `category_layers`: row block ℓ added to layer ℓ's inputs).
    let layer_rows: Option<Vec<f32>> = m.category_layers.as_ref().map(|table| {
        let all: Vec<f32> = table.weight.val().try_into_vec_as().unwrap();
        let c = category.unwrap_or(cfg.categories);
        let lw = cfg.layers * w;
        all[c * lw..(c + 1) * lw].to_vec()
    });
    let (mut hs, mut gs) = (vec![h0], vec![g0]);
    for (l, layer) in m.layers.iter().enumerate() {
        let add_layer = |x: &Vec<Vec<f32>>| -> Vec<Vec<f32>> {
            x.iter()
                .map(|row| match &layer_rows {
                    Some(r) => row
                        .iter()
                        .zip(&r[l * w..(l + 1) * w])
                        .map(|(a, b)| a + b)
                        .collect(),
                    None => row.clone(),
                })
                .collect()
        };
        let (vin, ein) = (add_layer(hs.last().unwrap()), add_layer(gs.last().unwrap()));
        let vb: Vec<Vec<f32>> = (0..K)
            .map(|i| {
                ref_silu(ref_linear(
                    &layer.node_bind,
                    &cat_all(&[&vin[i], pi(i), &tau]),
                ))
            })
            .collect();
        let eb: Vec<Vec<f32>> = (0..K * K)
            .map(|ij| ref_silu(ref_linear(&layer.edge_bind, &cat_all(&[&ein[ij], &tau]))))
            .collect();
        let u: Vec<Vec<f32>> = (0..K * K)
            .map(|ij| {
                let (i, j) = (ij / K, ij % K);
                let hidden = ref_silu(ref_linear(
                    &layer.edge_mlp1,
                    &cat_all(&[&vb[i], &vb[j], &eb[ij]]),
                ));
                ref_linear(&layer.edge_mlp2, &hidden)
            })
            .collect();
        let q: Vec<Vec<f32>> = vb.iter().map(|x| ref_linear(&layer.query, x)).collect();
        let k: Vec<Vec<f32>> = vb.iter().map(|x| ref_linear(&layer.key, x)).collect();
        let hc = cfg.head_channels;
        let mut v1 = vec![vec![0.0f32; w]; K];
        for i in 0..K {
            for head in 0..cfg.heads() {
                let ch = head * hc..(head + 1) * hc;
                let logits: Vec<f32> = (0..K)
                    .map(|j| {
                        ch.clone().map(|c| q[i][c] * k[j][c]).sum::<f32>()
                            / ((hc * 3) as f32).sqrt()
                    })
                    .collect();
                let mx = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                let ex: Vec<f32> = logits.iter().map(|a| (a - mx).exp()).collect();
                let sum: f32 = ex.iter().sum();
                for c in ch {
                    v1[i][c] = (0..K).map(|j| ex[j] / sum * u[i * K + j][c]).sum();
                }
            }
            let st = ref_silu(ref_linear(&layer.self_term, &vb[i]));
            v1[i].iter_mut().zip(st).for_each(|(a, b)| *a += b);
        }
        let pool: Vec<f32> = (0..w)
            .map(|c| (0..K).map(|i| v1[i][c]).fold(f32::NEG_INFINITY, f32::max))
            .collect();
        let v2 = (0..K)
            .map(|i| ref_silu(ref_linear(&layer.node_out, &cat_all(&[&v1[i], &pool]))))
            .collect();
        hs.push(v2);
        gs.push(u);
    }
    // §3.5 wide skip and heads.
    let mut out_v = Vec::new();
    for i in 0..K {
        let parts: Vec<&[f32]> = hs.iter().map(|h| h[i].as_slice()).collect();
        let hw = ref_linear(&m.node_wide, &cat_all(&parts));
        for (&(o, n), head) in NODE_SLICES.iter().zip(&m.node_heads) {
            out_v.extend(ref_mlp(head, cat_all(&[&hw, &node(i)[o..o + n]])));
        }
    }
    let mut out_e = Vec::new();
    for (idx, &(i, j)) in EDGE_PAIRS.iter().enumerate() {
        let parts: Vec<&[f32]> = gs.iter().map(|g| g[i * K + j].as_slice()).collect();
        let gw = ref_linear(&m.edge_wide, &cat_all(&parts));
        let row = &e[idx * EDGE_DIM..(idx + 1) * EDGE_DIM];
        for (&(o, n), head) in EDGE_SLICES.iter().zip(&m.edge_heads) {
            out_e.extend(ref_mlp(head, cat_all(&[&gw, &row[o..o + n]])));
        }
    }
    (out_v, out_e)
}

#[test]
fn batched_forward_matches_literal_reference() {
    for (legacy, category_layers) in [(false, false), (true, false), (false, true)] {
        let cfg = DenoiserConfig {
            width: 16,
            layers: 2,
            head_channels: 4,
            t_pe_dim: 12,
            slot_pe_dim: 6,
            node_head_hidden: vec![8, 6],
            edge_head_hidden: vec![8, 4],
            categories: 3,
            legacy_edge_embedding: legacy,
            category_layers,
        };
        let mut m = Denoiser::with_seed(&cfg, &cpu(), 7).unwrap();
        if let Some(table) = m.category_layers.as_mut() {
            // Zero-initialised; give it values so the reference has something to check.
            let shape = [cfg.categories + 1, cfg.layers * cfg.width];
            let vals = gaussian(&mut Rng::new(3), shape[0] * shape[1]);
            table.weight =
                Param::from_tensor(Tensor::from_data(TensorData::new(vals, shape), &cpu()));
        }
        let (v, e) = random_inputs(10, 2);
        let (bv, be) = run(&m, &v, &e, &[17, 640], Some(&[2, 3]));
        let (nv, ne) = (K * NODE_DIM, NUM_EDGES * EDGE_DIM);
        for (s, t, c) in [(0, 17, Some(2)), (1, 640, None)] {
            let (rv, re) =
                reference_forward(&m, &v[s * nv..(s + 1) * nv], &e[s * ne..(s + 1) * ne], t, c);
            let scale = rv.iter().chain(&re).fold(0.0f32, |a, x| a.max(x.abs()));
            let dv = max_abs_diff(&rv, &bv[s * nv..(s + 1) * nv]);
            let de = max_abs_diff(&re, &be[s * ne..(s + 1) * ne]);
            assert!(
                dv < 1e-4 * scale.max(1.0) && de < 1e-4 * scale.max(1.0),
                "legacy {legacy}, category layers {category_layers}, sample {s}: \
                 |Δε̂_V| {dv}, |Δε̂_E| {de} (scale {scale})"
            );
        }
    }
}

/// loss = Σ x̂₀ · R with x̂₀ = (x − √(1−ᾱ) ε̂(x)) / √ᾱ, and the pure Σ ε̂ · R, for ᾱ = 0.5.
fn host_losses(m: &Denoiser, v: &[f32], e: &[f32], rv: &[f32], re: &[f32]) -> (f64, f64) {
    let ab = 0.5f64;
    let (ev, ee) = run(m, v, e, &[250], None);
    let mut x0 = 0.0;
    let mut eps = 0.0;
    for (x, (ep, r)) in v
        .iter()
        .zip(ev.iter().zip(rv))
        .chain(e.iter().zip(ee.iter().zip(re)))
    {
        let xh = (*x as f64 - (1.0 - ab).sqrt() * *ep as f64) / ab.sqrt();
        x0 += xh * *r as f64;
        eps += *ep as f64 * *r as f64;
    }
    (x0, eps)
}

#[test]
fn input_gradient_matches_finite_differences() {
    let cfg = DenoiserConfig {
        width: 16,
        layers: 1,
        head_channels: 8,
        t_pe_dim: 8,
        slot_pe_dim: 4,
        node_head_hidden: vec![8],
        edge_head_hidden: vec![8],
        categories: 0,
        legacy_edge_embedding: false,
        category_layers: false,
    };
    // Model on the plain device (weights constant), inputs on the autodiff device — the
    // guidance set-up.
    let m = Denoiser::new(&cfg, &cpu()).unwrap();
    let (v, e) = random_inputs(8, 1);
    let mut rng = Rng::new(99);
    let rv = gaussian(&mut rng, v.len());
    let re = gaussian(&mut rng, e.len());
    let ad = cpu_autodiff();
    let ab = 0.5f32;

    let grads_of = |pure_eps: bool| -> (Vec<f32>, Vec<f32>) {
        let (vt, et) = tensors(&v, &e, &ad);
        let (vt, et) = (vt.require_grad(), et.require_grad());
        let (ev, ee) = m.forward(vt.clone(), et.clone(), ints(&[250], &ad), None);
        let (rvt, ret) = tensors(&rv, &re, &ad);
        let loss = if pure_eps {
            (ev * rvt).sum() + (ee * ret).sum()
        } else {
            let c = (1.0 - ab).sqrt();
            let x0v = (vt.clone() - ev * c) / ab.sqrt();
            let x0e = (et.clone() - ee * c) / ab.sqrt();
            (x0v * rvt).sum() + (x0e * ret).sum()
        };
        let g = loss.backward();
        (
            vec_of(vt.grad(&g).expect("v grad")),
            vec_of(et.grad(&g).expect("e grad")),
        )
    };
    let (gv0, ge0) = grads_of(false);
    let (gv1, ge1) = grads_of(true);

    let h = 3e-3f32;
    // (is_node, flat index): existence, a box, a latent; an edge class, l, a range.
    let picks = [
        (true, 2 * NODE_DIM),
        (true, 5 * NODE_DIM + 2),
        (true, 3 * NODE_DIM + 60),
        (false, 4 * EDGE_DIM + 1),
        (false, 9 * EDGE_DIM + edge_ch::DIR + 1),
        (false, 20 * EDGE_DIM + edge_ch::REVOLUTE),
    ];
    let mut worst = 0.0f64;
    let mut eps_grad = 0.0f64;
    for &(node, k) in &picks {
        let fd = |sign: f32| {
            let (mut vp, mut ep) = (v.clone(), e.clone());
            if node {
                vp[k] += sign * h;
            } else {
                ep[k] += sign * h;
            }
            host_losses(&m, &vp, &ep, &rv, &re)
        };
        let (p, z, n) = (fd(1.0), fd(0.0), fd(-1.0));
        let h2 = 2.0 * h as f64;
        // Central difference, and the one-sided ones as a fallback when ±h straddles a kink
        // (LeakyReLU, max-pool switch): then one side is smooth and matches to O(h).
        let diffs = |l: fn(&(f64, f64)) -> f64| {
            [
                (l(&p) - l(&n)) / h2,
                (l(&p) - l(&z)) / (h as f64),
                (l(&z) - l(&n)) / (h as f64),
            ]
        };
        let fd0 = diffs(|x| x.0);
        let fd1 = diffs(|x| x.1);
        let (a0, a1) = if node {
            (gv0[k] as f64, gv1[k] as f64)
        } else {
            (ge0[k] as f64, ge1[k] as f64)
        };
        for (fdx, adx) in [(fd0, a0), (fd1, a1)] {
            let rel = fdx
                .iter()
                .map(|f| (f - adx).abs() / f.abs().max(0.05))
                .fold(f64::INFINITY, f64::min);
            worst = worst.max(rel);
            assert!(
                rel < 3e-2,
                "grad mismatch at {} {k}: autodiff {adx}, finite differences {fdx:?}",
                if node { "v" } else { "e" }
            );
        }
        eps_grad += a1.abs();
    }
    // The denoiser Jacobian is a real part of the x̂₀ gradient (not just R/√ᾱ).
    assert!(eps_grad > 1e-2, "ε̂ gradient vanishes: {eps_grad}");
    assert!(worst.is_finite());
}

#[test]
fn weights_get_gradients_on_the_autodiff_device() {
    let ad = cpu_autodiff();
    let m = Denoiser::new(&tiny(4), &ad).unwrap();
    let (v, e) = random_inputs(9, 2);
    let (vt, et) = tensors(&v, &e, &ad);
    let (ev, ee) = m.forward(vt, et, ints(&[5, 700], &ad), Some(ints(&[1, 3], &ad)));
    let loss = ev.powi_scalar(2).mean() + ee.powi_scalar(2).mean();
    let grads = loss.backward();
    let g = m.layers[0]
        .edge_mlp1
        .weight
        .grad(&grads)
        .expect("weight grad");
    assert!(g.abs().sum().into_scalar::<f32>() > 0.0);
    let table = &m.category.as_ref().unwrap().weight;
    let gt: Vec<f32> = table
        .grad(&grads)
        .expect("table grad")
        .try_into_vec_as::<f32>()
        .unwrap();
    let w = m.config().width;
    let row_norm = |r: usize| gt[r * w..(r + 1) * w].iter().map(|x| x.abs()).sum::<f32>();
    assert!(row_norm(1) > 0.0 && row_norm(3) > 0.0);
    assert_eq!(row_norm(0), 0.0);
    assert_eq!(row_norm(4), 0.0); // "no category" unused here
}

#[test]
fn category_layers_start_as_the_plain_model_and_learn_per_category_rows() {
    let plain = tiny(4);
    let with = DenoiserConfig {
        category_layers: true,
        ..plain.clone()
    };
    let (a, b) = (
        Denoiser::new(&plain, &cpu()).unwrap(),
        Denoiser::new(&with, &cpu()).unwrap(),
    );
    // One extra (categories + 1) × (layers · w) table, drawn last and zero-initialised:
    // every other parameter is unchanged, so the untrained models agree.
    assert_eq!(
        b.parameter_count() - a.parameter_count(),
        5 * plain.layers * plain.width
    );
    let (v, e) = random_inputs(11, 2);
    assert_eq!(
        run(&a, &v, &e, &[40, 900], Some(&[1, 4])),
        run(&b, &v, &e, &[40, 900], Some(&[1, 4]))
    );
    // Only the rows of the categories in the batch get gradients.
    let ad = cpu_autodiff();
    let m = Denoiser::new(&with, &ad).unwrap();
    let (vt, et) = tensors(&v, &e, &ad);
    let (ev, ee) = m.forward(vt, et, ints(&[5, 700], &ad), Some(ints(&[1, 4], &ad)));
    let grads = (ev.powi_scalar(2).mean() + ee.powi_scalar(2).mean()).backward();
    let gt: Vec<f32> = m
        .category_layers
        .as_ref()
        .unwrap()
        .weight
        .grad(&grads)
        .expect("per-layer table grad")
        .try_into_vec_as::<f32>()
        .unwrap();
    let lw = with.layers * with.width;
    let row = |r: usize| {
        gt[r * lw..(r + 1) * lw]
            .iter()
            .map(|x| x.abs())
            .sum::<f32>()
    };
    assert!(row(1) > 0.0 && row(4) > 0.0, "{} {}", row(1), row(4));
    assert_eq!(row(0) + row(2) + row(3), 0.0);
    // The option needs a conditional model to mean anything: none without categories.
    let m0 = Denoiser::new(
        &DenoiserConfig {
            category_layers: true,
            ..tiny(0)
        },
        &cpu(),
    )
    .unwrap();
    assert_eq!(
        m0.parameter_count(),
        Denoiser::new(&tiny(0), &cpu()).unwrap().parameter_count()
    );
}
