//! physnap's inference networks against the independent PyTorch reference
//! (`scripts/torch_reference/`): golden inputs, outputs and input gradients that
//! `fixtures.py` wrote from PyTorch, for a tiny random denoiser, the shipped denoiser and the
//! shipped SDF decoder. The host path (what sampling and guidance run) and the burn module
//! must both reproduce them to 1e-4 relative. Rerun `fixtures.py` after changing the
//! inference path or the shipped weights (BENCHMARKS.md, "Against PyTorch").

use std::path::{Path, PathBuf};

use burn::tensor::{Int, Tensor, TensorData};
use physnap::graph::{EDGE_DIM, K, NODE_DIM, NUM_EDGES};
use physnap::io::npy;
use physnap::model::cpu;
use physnap::model::denoiser::host::{HostDenoiser, Workspace};
use physnap::model::denoiser::{Denoiser, DenoiserConfig};
use physnap::model::host_decoder::HostDecoder;

/// max |a − b| / max |b|: the tolerance is relative to the reference's scale.
const TOLERANCE: f64 = 1e-4;

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/torch_reference")
}

fn read(name: &str) -> Vec<f32> {
    let path = dir().join(format!("{name}.npy"));
    npy::read(&path)
        .unwrap_or_else(|e| panic!("fixture {}: {e}", path.display()))
        .2
}

fn rel(got: &[f32], want: &[f32]) -> f64 {
    assert_eq!(got.len(), want.len(), "lengths");
    let scale = want
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs() as f64))
        .max(1e-12);
    got.iter()
        .zip(want)
        .map(|(a, b)| (*a as f64 - *b as f64).abs())
        .fold(0.0, f64::max)
        / scale
}

fn assert_close(what: &str, got: &[f32], want: &[f32]) {
    let r = rel(got, want);
    assert!(
        r <= TOLERANCE,
        "{what}: {r:e} relative to PyTorch (limit {TOLERANCE:e})"
    );
}

fn tiny_model() -> Denoiser {
    let text = std::fs::read_to_string(dir().join("tiny_config.json")).expect("tiny config");
    let c: serde_json::Value = serde_json::from_str(&text).expect("json");
    let n = |k: &str| c[k].as_u64().expect("number") as usize;
    let list = |k: &str| -> Vec<usize> {
        c[k].as_array()
            .expect("list")
            .iter()
            .map(|x| x.as_u64().expect("n") as usize)
            .collect()
    };
    let cfg = DenoiserConfig {
        width: n("width"),
        layers: n("layers"),
        head_channels: n("head_channels"),
        t_pe_dim: n("t_pe_dim"),
        slot_pe_dim: n("slot_pe_dim"),
        node_head_hidden: list("node_head_hidden"),
        edge_head_hidden: list("edge_head_hidden"),
        categories: n("categories"),
        legacy_edge_embedding: c["legacy_edge_embedding"].as_bool().expect("bool"),
        category_layers: c["category_layers"].as_bool().expect("bool"),
    };
    let mut m = Denoiser::new(&cfg, &cpu()).expect("config");
    physnap::model::weights::load(&mut m, &dir().join("tiny_denoiser.safetensors"), None)
        .expect("tiny weights load");
    m
}

fn shipped() -> physnap::io::manifest::LoadedModels {
    let weights = Path::new(env!("CARGO_MANIFEST_DIR")).join("weights");
    physnap::io::manifest::load_models(&weights, &cpu()).expect("shipped weights")
}

fn check_denoiser(prefix: &str, model: &Denoiser) {
    let host = HostDenoiser::new(model);
    for case in ["mixed", "none"] {
        let base = format!("{prefix}_{case}_");
        let f = |n: &str| read(&format!("{base}{n}"));
        let t: Vec<usize> = f("t").iter().map(|&x| x as usize).collect();
        let b = t.len();
        let cats: Option<Vec<usize>> = dir()
            .join(format!("{base}category.npy"))
            .exists()
            .then(|| f("category").iter().map(|&x| x as usize).collect());
        let (v, e) = (f("v"), f("e"));
        let what = |x: &str| format!("{prefix} {case} {x}");

        // The host path: values and input gradients.
        let mut ws = Workspace::default();
        let (mut ev, mut ee) = (vec![0.0; v.len()], vec![0.0; e.len()]);
        host.forward(&v, &e, &t, cats.as_deref(), &mut ev, &mut ee, &mut ws, true);
        assert_close(&what("host ε̂_V"), &ev, &f("eps_v"));
        assert_close(&what("host ε̂_E"), &ee, &f("eps_e"));
        let (mut gv, mut ge) = (vec![0.0; v.len()], vec![0.0; e.len()]);
        host.backward(&mut ws, &f("r_v"), &f("r_e"), &mut gv, &mut ge);
        assert_close(&what("host ∂/∂V"), &gv, &f("grad_v"));
        assert_close(&what("host ∂/∂E"), &ge, &f("grad_e"));

        // The burn module (what training runs): values.
        let device = cpu();
        let ints = |x: &[usize]| {
            Tensor::<1, Int>::from_data(
                TensorData::new(x.iter().map(|&x| x as i64).collect::<Vec<_>>(), [b]),
                &device,
            )
        };
        let (bv, be) = model.forward(
            Tensor::from_data(TensorData::new(v.clone(), [b, K, NODE_DIM]), &device),
            Tensor::from_data(
                TensorData::new(e.clone(), [b, NUM_EDGES, EDGE_DIM]),
                &device,
            ),
            ints(&t),
            cats.as_deref().map(ints),
        );
        let flat = |x: Tensor<3>| x.into_data().try_to_vec::<f32>().expect("f32");
        assert_close(&what("burn ε̂_V"), &flat(bv), &f("eps_v"));
        assert_close(&what("burn ε̂_E"), &flat(be), &f("eps_e"));
    }
}

#[test]
fn tiny_denoiser_matches_pytorch() {
    check_denoiser("tiny", &tiny_model());
}

#[test]
fn shipped_denoiser_matches_pytorch() {
    check_denoiser("shipped", &shipped().denoiser);
}

#[test]
fn shipped_decoder_matches_pytorch() {
    let models = shipped();
    let host = HostDecoder::new(&models.shape_prior.decoder);
    let points: Vec<[f32; 3]> = read("decoder_points")
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    let idx: Vec<usize> = read("decoder_index").iter().map(|&x| x as usize).collect();
    let g = host.eval_with_grads(&points, &read("decoder_features"), &idx);
    assert_close("decoder f", &g.values, &read("decoder_sdf"));
    let d_points: Vec<f32> = g.d_points.iter().flatten().copied().collect();
    assert_close("decoder ∂f/∂q", &d_points, &read("decoder_grad_points"));
    assert_close(
        "decoder ∂f/∂features",
        &g.d_features,
        &read("decoder_grad_features"),
    );
}
