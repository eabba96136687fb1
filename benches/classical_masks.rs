//! The classical segmenter's three levels on one 1000 px view: what a `segment_then_splat` job
//! without a SAM model spends per view before training (issue 38, item 5). Timed on all cores (the
//! levels in parallel, as one view alone runs) and on one thread (the CPU-seconds a view costs,
//! which a job segmenting all its views at once spreads over the machine's cores).
//!
//! The view is the figurine's first photo when `../shared/data/figurine` is beside the checkout
//! (or `SEGSPLAT_BENCH_IMAGE` names an image), else a synthetic 1000 x 665 scene of shaded
//! shapes over a noisy background. Run: `cargo bench --bench classical_masks`. Under `cargo test
//! --all-targets` each bench runs once. Figures: docs/benchmarks.md, "Classical masks faster".

use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use image::{Rgb, RgbImage};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use segsplat_vision::segment::{ClassicalConfig, classical_masks};
use sha2::{Digest, Sha256};

const LONG_SIDE: u32 = 1000;

/// The image `SEGSPLAT_BENCH_IMAGE` names (which must open), else the figurine's first photo
/// when it is beside the checkout, at most 1000 px on its long side.
fn photo() -> Option<RgbImage> {
    let image = match std::env::var_os("SEGSPLAT_BENCH_IMAGE").map(PathBuf::from) {
        Some(path) => image::open(&path)
            .unwrap_or_else(|error| panic!("SEGSPLAT_BENCH_IMAGE={}: {error}", path.display())),
        None => image::open(
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../shared/data/figurine/images/DSC_5283.jpg"),
        )
        .ok()?,
    }
    .to_rgb8();
    let (width, height) = image.dimensions();
    let scale = LONG_SIDE as f32 / width.max(height) as f32;
    if scale >= 1.0 {
        return Some(image);
    }
    let size = |side: u32| ((side as f32 * scale).round() as u32).max(1);
    Some(image::imageops::resize(
        &image,
        size(width),
        size(height),
        image::imageops::FilterType::Triangle,
    ))
}

/// Discs and boxes of flat colours with a lighting ramp, over sensor-like noise.
fn synthetic() -> RgbImage {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let shapes: Vec<([f32; 4], [u8; 3], bool)> = (0..40)
        .map(|_| {
            let centre = [rng.random_range(0.0..1000.0), rng.random_range(0.0..665.0)];
            let half = [rng.random_range(15.0..140.0), rng.random_range(15.0..140.0)];
            let colour = std::array::from_fn(|_| rng.random_range(20..235));
            (
                [centre[0], centre[1], half[0], half[1]],
                colour,
                rng.random_bool(0.5),
            )
        })
        .collect();
    let mut image = RgbImage::from_fn(LONG_SIDE, 665, |x, y| {
        let (x, y) = (x as f32, y as f32);
        let mut colour = [90u8, 110, 100];
        for &([cx, cy, hx, hy], shape_colour, disc) in &shapes {
            let (dx, dy) = ((x - cx) / hx, (y - cy) / hy);
            let inside = if disc {
                dx * dx + dy * dy <= 1.0
            } else {
                dx.abs() <= 1.0 && dy.abs() <= 1.0
            };
            if inside {
                let shade = 0.75 + 0.25 * (1.0 - dy.clamp(-1.0, 1.0)) / 2.0;
                colour = shape_colour.map(|c| (f32::from(c) * shade) as u8);
            }
        }
        Rgb(colour)
    });
    for pixel in image.pixels_mut() {
        for channel in pixel.0.iter_mut() {
            *channel = channel.saturating_add_signed(rng.random_range(-6..=6));
        }
    }
    image
}

fn bench(c: &mut Criterion) {
    let (image, source) = match photo() {
        Some(image) => (image, "figurine DSC_5283"),
        None => (synthetic(), "synthetic"),
    };
    let config = ClassicalConfig::default();
    let masks = classical_masks(&image, &config).expect("the bench's image segments");
    // The masks' digest: a change to the segmenter's speed must leave it as it was.
    let mut digest = Sha256::new();
    for mask in masks.levels.iter().flatten() {
        digest.update(
            mask.mask
                .to_bools()
                .iter()
                .map(|&set| set as u8)
                .collect::<Vec<_>>(),
        );
    }
    let digest = digest.finalize();
    println!(
        "classical_masks: {source}, {}x{}, masks per level {:?}, sha256 {:x}",
        image.width(),
        image.height(),
        masks.levels.each_ref().map(Vec::len),
        digest
    );
    let mut group = c.benchmark_group("classical_masks");
    group.sample_size(10);
    group.bench_function("three levels, every core", |b| {
        b.iter(|| classical_masks(&image, &config))
    });
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    group.bench_function("three levels, one thread", |b| {
        b.iter(|| one_thread.install(|| classical_masks(&image, &config)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
