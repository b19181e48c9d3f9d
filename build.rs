//! Compiles `proto/physnap/v1/jobs.proto` with protox (pure Rust), so building needs no system
//! `protoc`; the descriptor set also feeds gRPC reflection.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let proto = "proto/physnap/v1/jobs.proto";
    println!("cargo:rerun-if-changed={proto}");
    let fds = protox::compile([proto], ["proto"])?;
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(
        out.join("physnap_v1_descriptor.bin"),
        prost::Message::encode_to_vec(&fds),
    )?;
    tonic_prost_build::configure()
        .build_client(true)
        .build_server(true)
        .compile_fds(fds)?;
    Ok(())
}
