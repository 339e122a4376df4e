//! Compiles `glint/v1/*.proto` with protox (pure Rust, no system `protoc`) and generates the
//! prost messages and tonic services with tonic-prost-build.
//!
//! Imports are rooted at this crate's directory (`proto/`), the same root Python's
//! `grpc_tools.protoc -I proto` uses.

use std::error::Error;
use std::path::PathBuf;
use std::{env, fs};

fn main() -> Result<(), Box<dyn Error>> {
    let root = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let package_dir = root.join("glint").join("v1");

    let mut protos: Vec<PathBuf> = fs::read_dir(&package_dir)?
        .map(|entry| entry.map(|e| e.path()))
        .collect::<Result<_, _>>()?;
    protos.retain(|p| p.extension().is_some_and(|ext| ext == "proto"));
    protos.sort();
    if protos.is_empty() {
        return Err(format!("no .proto files in {}", package_dir.display()).into());
    }

    // A directory makes Cargo rescan it, so new files trigger a rebuild too.
    println!("cargo:rerun-if-changed={}", root.join("glint").display());
    println!("cargo:rerun-if-changed=build.rs");
    for proto in &protos {
        println!("cargo:rerun-if-changed={}", proto.display());
    }

    // protox's error is a miette diagnostic; its Debug form names the file, line and column.
    let fds = protox::compile(&protos, [&root]).map_err(|e| format!("protox: {e:?}"))?;

    // Keep the encoded descriptor set for gRPC server reflection.
    let out_dir = PathBuf::from(env::var("OUT_DIR")?);
    fs::write(
        out_dir.join("glint_descriptor.bin"),
        prost::Message::encode_to_vec(&fds),
    )?;

    tonic_prost_build::configure().compile_fds(fds)?;
    Ok(())
}
