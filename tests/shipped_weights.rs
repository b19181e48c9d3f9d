//! The weights shipped in `weights/` load (sha256 and configs checked), and sampling with them
//! is deterministic for a seed — what `physnap generate`, `physnap serve` and the README's
//! first command rely on. A copy with one flipped byte is refused.

use std::ops::ControlFlow;
use std::path::Path;

use physnap::engine::generate::{GenerateRequest, generate};
use physnap::engine::schedule::Schedule;
use physnap::io::manifest::load_models;
use physnap::mesh::MeshingOptions;
use physnap::model::shape_prior::LatentSdfDecoder;

fn weights() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("weights").leak()
}

#[test]
fn shipped_weights_load_and_sample_deterministically() {
    let dev = physnap::model::cpu();
    let models = load_models(weights(), &dev).expect("weights/ must hold loadable weights");
    assert_eq!(models.manifest.categories.len(), 46);
    assert!(models.manifest.denoiser.config.categories > 0);
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let category = models
        .manifest
        .categories
        .iter()
        .position(|c| c == "StorageFurniture");
    let run = || {
        let req = GenerateRequest {
            seed: 7,
            samples: 1,
            category,
            category_name: Some("StorageFurniture".into()),
            meshing: MeshingOptions { resolution: 16 },
            ..Default::default()
        };
        generate(
            &models.denoiser,
            &decoder,
            models.codebook.as_ref(),
            &models.manifest.feature_scales,
            &Schedule::default(),
            &req,
            &mut |_| ControlFlow::Continue(()),
        )
        .expect("sampling with the shipped weights")
    };
    let (a, b) = (run(), run());
    assert_eq!(a[0].raw, b[0].raw, "same seed, same raw graph");
    assert_eq!(
        physnap::io::object_json::to_string(&a[0].object),
        physnap::io::object_json::to_string(&b[0].object)
    );
    assert!(!a[0].object.parts.is_empty());
}

#[test]
fn a_corrupted_copy_of_the_shipped_weights_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    for f in [
        "manifest.json",
        "denoiser.safetensors",
        "shape_prior.safetensors",
    ] {
        std::fs::copy(weights().join(f), dir.path().join(f)).unwrap();
    }
    let path = dir.path().join("denoiser.safetensors");
    let mut bytes = std::fs::read(&path).unwrap();
    let k = bytes.len() - 100;
    bytes[k] ^= 0x40;
    std::fs::write(&path, bytes).unwrap();
    let e = match load_models(dir.path(), &physnap::model::cpu()) {
        Ok(_) => panic!("a corrupted file must be refused"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("denoiser.safetensors") && e.contains("sha256"),
        "{e}"
    );
}
