//! Upload and download throughput of the S3 blob store, and the process's peak memory while it
//! streams: a file of `SEGSPLAT_BENCH_UPLOAD_MIB` MiB (default 64; the docs' figure uses 1024)
//! is written to disk, stored with `put_file` (multipart, 8 MiB parts), fetched back with
//! `get_to_path`, compared, and deleted. Peak resident memory (`VmHWM`) before and after shows
//! the file is never held whole.
//!
//! Needs an S3-compatible server: `scripts/test_servers.sh` starts one and exports
//! `SEGSPLAT_TEST_S3_ENDPOINT` / `SEGSPLAT_TEST_S3_BUCKET`. Without them it says so and exits.
//! Run: `SEGSPLAT_BENCH_UPLOAD_MIB=1024 cargo bench --bench blob_upload` (docs/benchmarks.md).

mod support;

use std::io::{Read, Write};
use std::time::Instant;

use segsplat_service::store::{BlobStore, ObjectBlobStore};

fn same_contents(left: &std::path::Path, right: &std::path::Path) -> std::io::Result<bool> {
    let (mut left, mut right) = (std::fs::File::open(left)?, std::fs::File::open(right)?);
    let (mut a, mut b) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    loop {
        let read = left.read(&mut a)?;
        if read == 0 {
            return Ok(right.read(&mut b)? == 0);
        }
        right.read_exact(&mut b[..read])?;
        if a[..read] != b[..read] {
            return Ok(false);
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Some(config) = support::s3_test_bucket("blob_upload") else {
        return Ok(());
    };
    let mib: usize = std::env::var("SEGSPLAT_BENCH_UPLOAD_MIB")
        .ok()
        .and_then(|value| value.parse().ok())
        .unwrap_or(64);
    let url = config.url.clone().unwrap_or_default();
    let store = ObjectBlobStore::open(&config, &url)?;

    let dir = tempfile::tempdir()?;
    let source = dir.path().join("archive.bin");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&source)?);
    let mut block = vec![0u8; 1 << 20];
    for index in 0..mib {
        // Varying bytes, so nothing on the way can compress them.
        for (offset, byte) in block.iter_mut().enumerate() {
            *byte = (offset.wrapping_mul(31) ^ index.wrapping_mul(131)) as u8;
        }
        file.write_all(&block)?;
    }
    file.flush()?;
    drop(file);
    drop(block);
    let before = support::peak_resident_mib();

    let started = Instant::now();
    store.put_file("bench/archive.bin", &source)?;
    let upload_secs = started.elapsed().as_secs_f64();
    let after_upload = support::peak_resident_mib();
    let fetched = dir.path().join("fetched.bin");
    let started = Instant::now();
    store.get_to_path("bench/archive.bin", &fetched)?;
    let download_secs = started.elapsed().as_secs_f64();
    let after_download = support::peak_resident_mib();
    let identical = same_contents(&source, &fetched)?;
    store.delete_prefix("bench")?;
    println!(
        "{{\"mib\":{mib},\"upload_mib_per_s\":{:.1},\"download_mib_per_s\":{:.1},\
         \"peak_resident_mib_before\":{before:.1},\"peak_resident_mib_after_upload\":\
         {after_upload:.1},\"peak_resident_mib_after_download\":{after_download:.1},\
         \"identical\":{identical}}}",
        mib as f64 / upload_secs,
        mib as f64 / download_secs,
    );
    if !identical {
        return Err("the fetched file differs from the uploaded one".into());
    }
    Ok(())
}
