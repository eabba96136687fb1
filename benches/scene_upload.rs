//! A large scene upload end to end into an S3-compatible bucket: `POST /v1/scenes` with a
//! stored (uncompressed) zip of about `SEGSPLAT_BENCH_ARCHIVE_MIB` MiB (default 32; the docs'
//! figure uses 1024) of COLMAP frames whose pixels carry noise, so PNG cannot shrink them. The
//! request body is streamed from disk; the service receives it to disk, unpacks, validates every
//! image and streams each file to the bucket (multipart past 8 MiB). Reported: archive MiB/s
//! from the first byte sent to the 201, and the process's peak resident memory (`VmHWM`) before
//! and after, which shows that the archive is never held whole in memory.
//!
//! Needs an S3-compatible server: `scripts/test_servers.sh` starts one and exports
//! `SEGSPLAT_TEST_S3_ENDPOINT` / `SEGSPLAT_TEST_S3_BUCKET`. Without them it says so and exits.
//! Run: `SEGSPLAT_BENCH_ARCHIVE_MIB=1024 cargo bench --bench scene_upload` (docs/benchmarks.md).

mod support;

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use segsplat_api::ServiceBuilder;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{SyntheticSpec, write_colmap};
use segsplat_service::config::Config;

const WIDTH: u32 = 2048;
const HEIGHT: u32 = 1536;

/// Adds noise to every pixel of the PNG at `path` (same size), so it no longer compresses.
fn add_noise(path: &Path, seed: u64) -> Result<(), Box<dyn std::error::Error>> {
    let mut image = image::open(path)?.to_rgb8();
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    for pixel in image.pixels_mut() {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        for (channel, noise) in pixel.0.iter_mut().zip(state.to_le_bytes()) {
            *channel = channel.wrapping_add(noise & 0x3f);
        }
    }
    image.save(path)?;
    Ok(())
}

/// Writes the dataset and zips it (stored) into `archive`; returns the archive's size.
fn write_archive(
    dataset: &Path,
    archive: &Path,
    mib: usize,
) -> Result<u64, Box<dyn std::error::Error>> {
    let frame_mib = (WIDTH * HEIGHT * 3) as f64 / (1024.0 * 1024.0);
    let frames = ((mib as f64 / frame_mib).ceil() as usize).max(3);
    let spec = SyntheticSpec {
        frame_count: frames,
        width: WIDTH,
        height: HEIGHT,
        ..SyntheticSpec::default()
    };
    write_colmap(dataset, &spec, ColmapEncoding::Binary)?;
    let mut images: Vec<_> = std::fs::read_dir(dataset.join("images"))?
        .filter_map(Result::ok)
        .map(|entry| entry.path())
        .collect();
    images.sort();
    for (seed, image) in images.iter().enumerate() {
        add_noise(image, seed as u64)?;
    }
    let mut zip = zip::ZipWriter::new(std::fs::File::create(archive)?);
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .large_file(true);
    let mut stack = vec![dataset.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir)? {
            let path = entry?.path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            let name = path.strip_prefix(dataset)?.to_string_lossy().into_owned();
            zip.start_file(name, options)?;
            std::io::copy(&mut std::fs::File::open(&path)?, &mut zip)?;
        }
    }
    zip.finish()?.flush()?;
    Ok(std::fs::metadata(archive)?.len())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Some(blobs) = support::s3_test_bucket("scene_upload") else {
        return Ok(());
    };
    let mib: usize = std::env::var("SEGSPLAT_BENCH_ARCHIVE_MIB")
        .ok()
        .and_then(|value| value.parse().ok())
        .unwrap_or(32);
    let work = tempfile::tempdir()?;
    let archive = work.path().join("scene.zip");
    let archive_bytes = write_archive(&work.path().join("dataset"), &archive, mib)?;
    let archive_mib = archive_bytes as f64 / (1024.0 * 1024.0);

    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(async {
        let mut config = Config {
            data_dir: work.path().join("data"),
            http_addr: "127.0.0.1:0".parse()?,
            grpc_addr: "127.0.0.1:0".parse()?,
            ..Config::default()
        };
        config.workers.enabled = false;
        config.limits.max_upload_bytes = 8 << 30;
        config.blobs = blobs;
        let service = ServiceBuilder::new(config)
            .detect_gpus(false)
            .start()
            .await?;
        let url = format!("http://{}/v1/scenes", service.http_addr().ok_or("no http")?);
        // Forget the peak the archive's generation reached: from here it is the service's.
        std::fs::write("/proc/self/clear_refs", "5")?;
        let peak_before = support::peak_resident_mib();
        let started = Instant::now();
        let body = reqwest::Body::wrap_stream(tokio_util::io::ReaderStream::new(
            tokio::fs::File::open(&archive).await?,
        ));
        let response = reqwest::Client::new()
            .post(&url)
            .header("content-type", "application/zip")
            .header("content-length", archive_bytes)
            .body(body)
            .send()
            .await?;
        let status = response.status();
        let text = response.text().await?;
        let seconds = started.elapsed().as_secs_f64();
        if status.as_u16() != 201 {
            return Err(format!("upload answered {status}: {text}").into());
        }
        println!(
            "scene_upload: {archive_mib:.0} MiB archive ({} x {WIDTH}x{HEIGHT} noisy PNG \
             frames) -> 201 in {seconds:.1} s = {:.1} MiB/s; peak RSS {peak_before:.1} -> \
             {:.1} MiB",
            ((mib as f64) / ((WIDTH * HEIGHT * 3) as f64 / 1048576.0))
                .ceil()
                .max(3.0),
            archive_mib / seconds,
            support::peak_resident_mib(),
        );
        service.shutdown().await;
        Ok::<(), Box<dyn std::error::Error>>(())
    })
}
