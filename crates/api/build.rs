//! Compiles the gRPC protos with protox (pure Rust), so no system `protoc` is needed.

use std::path::PathBuf;

/// The commit being built, for `segsplat_build_info`: `SEGSPLAT_GIT_COMMIT` when the build sets
/// it (an image built without `.git`), else `git rev-parse`, else `unknown`. Reruns when HEAD
/// moves (only paths that exist are watched: a missing one would rerun every build).
fn git_commit() -> String {
    println!("cargo:rerun-if-env-changed=SEGSPLAT_GIT_COMMIT");
    if let Ok(commit) = std::env::var("SEGSPLAT_GIT_COMMIT") {
        return commit;
    }
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|output| output.status.success())
            .map(|output| String::from_utf8_lossy(&output.stdout).trim().to_string())
    };
    for path in [
        git(&["rev-parse", "--git-path", "HEAD"]),
        git(&["rev-parse", "--symbolic-full-name", "HEAD"])
            .and_then(|name| git(&["rev-parse", "--git-path", &name])),
    ]
    .into_iter()
    .flatten()
    {
        if std::path::Path::new(&path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    }
    git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".to_string())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rustc-env=SEGSPLAT_GIT_COMMIT={}", git_commit());
    let protos = ["proto/segsplat/v1/segsplat.proto"];
    for proto in protos {
        println!("cargo:rerun-if-changed={proto}");
    }
    let file_descriptors = protox::compile(protos, ["proto"])?;
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    let descriptor_path = out_dir.join("segsplat_descriptor.bin");
    std::fs::write(
        &descriptor_path,
        prost::Message::encode_to_vec(&file_descriptors),
    )?;
    tonic_prost_build::configure()
        .file_descriptor_set_path(&descriptor_path)
        .skip_protoc_run()
        .compile_fds(file_descriptors)?;
    Ok(())
}
