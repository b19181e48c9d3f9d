//! Architecture invariant (ARCHITECTURE.md): the engine and its core never depend on transport
//! or serialisation crates. This test reads the sources, so a stray `use serde_json` in the
//! engine fails CI instead of eroding the boundary.

use std::path::Path;

const TRANSPORT_FREE: &[&str] = &[
    "src/object.rs",
    "src/graph",
    "src/kinematics.rs",
    "src/shape.rs",
    "src/mesh",
    "src/model",
    "src/engine",
    "src/eval",
    "src/sim.rs",
    "src/frame.rs",
];
const FORBIDDEN: &[&str] = &[
    "serde", "axum", "tonic", "prost", "utoipa", "tokio", "rusqlite", "reqwest",
];

fn rust_files(p: &Path, out: &mut Vec<std::path::PathBuf>) {
    if p.is_dir() {
        for e in std::fs::read_dir(p).unwrap() {
            rust_files(&e.unwrap().path(), out);
        }
    } else if p.extension().is_some_and(|e| e == "rs") {
        out.push(p.to_path_buf());
    }
}

#[test]
fn engine_and_core_are_transport_free() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for p in TRANSPORT_FREE {
        rust_files(&root.join(p), &mut files);
    }
    assert!(
        files.len() > 10,
        "expected the core sources, found {files:?}"
    );
    let mut offences = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            for word in FORBIDDEN {
                if code.contains(&format!("{word}::")) || code.contains(&format!("use {word}")) {
                    offences.push(format!("{}:{}: {}", f.display(), n + 1, line.trim()));
                }
            }
        }
    }
    assert!(
        offences.is_empty(),
        "transport/serialisation imports in the engine:\n{}",
        offences.join("\n")
    );
}
