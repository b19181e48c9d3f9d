//! Write tiny, untrained but complete weights into a folder: `tiny_weights DIR`.
//!
//! Why it exists: the API fuzzing run (`scripts/ci-schemathesis.sh`) needs a live server whose
//! jobs run the real engine in milliseconds; the tests build the same weights in-process
//! ([`physnap::fixtures::tiny_weights`]).

fn main() {
    let Some(dir) = std::env::args_os().nth(1) else {
        eprintln!("usage: tiny_weights DIR");
        std::process::exit(2);
    };
    if let Err(e) = physnap::fixtures::tiny_weights(std::path::Path::new(&dir)) {
        eprintln!("tiny_weights: {e}");
        std::process::exit(1);
    }
}
