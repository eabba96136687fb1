//! Writes `crates/api/src/generated/`: the Rust code of `segsplat.v1` (messages, client and
//! server), its encoded file descriptors for gRPC reflection, and the SHA-256 of the proto it
//! came from, which a test of `segsplat-api` compares with the proto in the tree so that a proto
//! changed without regenerating fails the suite. Run from the repository root:
//! `bash scripts/protogen.sh`.

use std::path::Path;

use sha2::{Digest, Sha256};

const PROTO_ROOT: &str = "crates/api/proto";
const PROTO: &str = "segsplat/v1/segsplat.proto";
const OUT: &str = "crates/api/src/generated";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let proto_path = Path::new(PROTO_ROOT).join(PROTO);
    let proto_text = std::fs::read(&proto_path)
        .map_err(|error| format!("cannot read {}: {error}", proto_path.display()))?;
    let file_descriptors = protox::compile([PROTO], [PROTO_ROOT])?;
    let out = Path::new(OUT);
    std::fs::create_dir_all(out)?;
    std::fs::write(
        out.join("segsplat_descriptor.bin"),
        prost::Message::encode_to_vec(&file_descriptors),
    )?;
    tonic_prost_build::configure()
        .out_dir(out)
        .skip_protoc_run()
        .compile_fds(file_descriptors)?;
    let digest = Sha256::digest(&proto_text);
    let hex: String = digest.iter().map(|byte| format!("{byte:02x}")).collect();
    std::fs::write(out.join("proto.sha256"), format!("{hex}  {PROTO}\n"))?;
    println!("wrote {OUT}/segsplat.v1.rs, segsplat_descriptor.bin and proto.sha256");
    Ok(())
}
