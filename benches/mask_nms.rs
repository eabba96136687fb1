//! Per-level NMS of automatic masks: 1000 candidate masks at 1000x660 through box NMS and mask
//! NMS (`postprocess_level` with small-region removal off), through mask NMS alone (box NMS off,
//! so all 1000 masks meet pairwise), and the full level post-processing (with SAM's small-region
//! removal at 100 px).
//!
//! Candidates look like a SAM level after the IoU/stability filters: ~170 objects (ellipses and
//! rectangles from 5 to 200 px across, many overlapping), each answered several times with
//! jittered near-duplicates, plus parts nested inside larger objects.
//!
//! Run: `cargo bench --bench mask_nms`. Under `cargo test --all-targets` each bench runs once.
//! Measured on the 2-core development machine (release, other builds running, criterion
//! median): box + mask NMS 2.0 ms, mask NMS alone over all 1000 7.6 ms, full level with
//! small-region removal 57 ms (docs/segment.md).

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use segsplat_vision::segment::{AutomaticConfig, BitMask, ScoredMask, postprocess_level};

const WIDTH: u32 = 1000;
const HEIGHT: u32 = 660;
const CANDIDATES: usize = 1000;

/// An axis-aligned ellipse or rectangle.
#[derive(Clone, Copy)]
struct Blob {
    centre: [f32; 2],
    half_size: [f32; 2],
    rectangle: bool,
}

impl Blob {
    fn rasterise(&self) -> BitMask {
        let mut mask = BitMask::new(WIDTH, HEIGHT);
        let [cx, cy] = self.centre;
        let [hx, hy] = self.half_size;
        let y_first = (cy - hy).floor().max(0.0) as u32;
        let y_last = ((cy + hy).ceil() as u32).min(HEIGHT - 1);
        for y in y_first..=y_last {
            let dy = (y as f32 + 0.5 - cy) / hy;
            if dy.abs() > 1.0 {
                continue;
            }
            let half_width = if self.rectangle {
                hx
            } else {
                hx * (1.0 - dy * dy).sqrt()
            };
            let start = (cx - half_width).round().max(0.0) as u32;
            let end = (cx + half_width).round().max(0.0) as u32;
            mask.set_row_span(y, start..end, true);
        }
        mask
    }
}

fn candidates() -> Vec<ScoredMask> {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut blobs = Vec::with_capacity(CANDIDATES);
    while blobs.len() < CANDIDATES {
        // Log-uniform sizes: many small objects, few large ones.
        let radius = 2.5f32 * 40f32.powf(rng.random::<f32>());
        let object = Blob {
            centre: [
                rng.random_range(0.0..WIDTH as f32),
                rng.random_range(0.0..HEIGHT as f32),
            ],
            half_size: [
                radius * rng.random_range(0.6..1.6),
                radius * rng.random_range(0.6..1.6),
            ],
            rectangle: rng.random_bool(0.3),
        };
        // The object answered by several prompts: near-duplicates.
        let answers = rng.random_range(2..=6);
        for _ in 0..answers {
            let jitter = 0.04 * radius;
            blobs.push(Blob {
                centre: [
                    object.centre[0] + rng.random_range(-jitter..=jitter),
                    object.centre[1] + rng.random_range(-jitter..=jitter),
                ],
                half_size: object
                    .half_size
                    .map(|half| half * rng.random_range(0.95..1.05)),
                ..object
            });
        }
        // Sometimes a part nested in it (an inner mask).
        if rng.random_bool(0.25) {
            blobs.push(Blob {
                half_size: object.half_size.map(|half| half * 0.4),
                ..object
            });
        }
    }
    blobs.truncate(CANDIDATES);
    blobs
        .iter()
        .filter_map(|blob| {
            let mask = blob.rasterise();
            let bbox = mask.bounding_box()?;
            let predicted_iou = rng.random_range(0.7..1.0);
            let stability = rng.random_range(0.85..1.0);
            Some(ScoredMask {
                area: mask.area(),
                mask,
                bbox,
                predicted_iou,
                stability,
                score: predicted_iou * stability,
                point: Some(blob.centre),
                instance_id: None,
            })
        })
        .collect()
}

fn bench_mask_nms(criterion: &mut Criterion) {
    let candidates = candidates();
    let nms_only = AutomaticConfig {
        min_mask_region_area: 0,
        ..AutomaticConfig::default()
    };
    let full = AutomaticConfig::default();
    // Box NMS off (no box IoU is above 1): mask NMS alone over all 1000 candidates, the
    // pairwise worst case.
    let mask_nms_only = AutomaticConfig {
        box_nms_thresh: 1.0,
        ..nms_only.clone()
    };
    eprintln!(
        "mask_nms: {} candidates at {WIDTH}x{HEIGHT}; kept: {} by box + mask NMS, {} by mask NMS \
         alone, {} by full post-processing",
        candidates.len(),
        postprocess_level(candidates.clone(), &nms_only).len(),
        postprocess_level(candidates.clone(), &mask_nms_only).len(),
        postprocess_level(candidates.clone(), &full).len(),
    );
    let mut group = criterion.benchmark_group("mask_nms");
    group.sample_size(10);
    group.bench_function("box_and_mask_nms_1000_at_1000x660", |bencher| {
        bencher.iter_batched(
            || candidates.clone(),
            |input| postprocess_level(input, &nms_only),
            BatchSize::LargeInput,
        )
    });
    group.bench_function("mask_nms_alone_1000_at_1000x660", |bencher| {
        bencher.iter_batched(
            || candidates.clone(),
            |input| postprocess_level(input, &mask_nms_only),
            BatchSize::LargeInput,
        )
    });
    group.bench_function("full_level_postprocess_1000_at_1000x660", |bencher| {
        bencher.iter_batched(
            || candidates.clone(),
            |input| postprocess_level(input, &full),
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

criterion_group!(benches, bench_mask_nms);
criterion_main!(benches);
