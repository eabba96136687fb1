//! Densification on the GPU (`densify::gpu::GpuDensifier`) against the CPU plan
//! (`densify::plan_densification` + `DensifyPlan::apply` / `gather`) on random models: the same
//! survivors in the same order, the same clones and split children, the same object ids and
//! optimiser moments (kept rows keep theirs, new rows start at zero), with and without a growth
//! bound and a prune guard. Everything is compared exactly except the split children's means,
//! which go through `exp`, `log`, `sin` and `cos` on each side (within 1e-5 of the parent's
//! largest scale). Mean gradients are drawn as exact quotients (visible counts are powers of
//! two), so the GPU's division cannot reorder the ranking.

mod gpu_support;

use gpu_support::{gpu_context, seeded_rng, storage_buffer};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use segsplat_engine::densify::gpu::{
    DensifyInput, DensifyRequest, DensifySummary, GpuDensifier, StatBuffers,
};
use segsplat_engine::densify::{
    DensifyConfig, DensifyStats, ObjectFloor, PruneGuard, plan_densification, reset_opacity_logits,
};
use segsplat_engine::model::{GaussianParameterBuffers, SH_COEFFICIENTS};
use segsplat_engine::{GaussianModel, GpuGaussians, OBJECT_NONE};
use segsplat_gpu::GpuContext;

const EXTENT: f32 = 2.0;

struct Case {
    model: GaussianModel,
    first: GaussianModel,
    second: GaussianModel,
    stats: DensifyStats,
}

fn random_rows(rng: &mut ChaCha8Rng, count: usize, ids: bool) -> GaussianModel {
    let mut model = GaussianModel::default();
    for _ in 0..count {
        let mut sh = [[0.0f32; 3]; SH_COEFFICIENTS];
        for coefficient in sh.iter_mut() {
            *coefficient = [rng.random(), rng.random(), rng.random()];
        }
        let object = |rng: &mut ChaCha8Rng| {
            if rng.random_bool(0.2) {
                OBJECT_NONE
            } else {
                rng.random_range(0..6)
            }
        };
        model.means.push([rng.random(), rng.random(), rng.random()]);
        // Largest scales log-uniform from 0.002 to 0.2 of the extent: both sides of the
        // clone/split line (0.01 of it) and of the oversized-pruning line (0.1).
        let largest = EXTENT * rng.random_range(0.002f32.ln()..0.2f32.ln()).exp();
        model
            .log_scales
            .push([1.0, 0.7, 0.4].map(|share: f32| (largest * share).ln()));
        model.rotations.push([
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(0.1..1.0),
        ]);
        model.opacity_logits.push(rng.random_range(-7.0..4.0));
        model.sh_coefficients.push(sh);
        model.object_ids.push(if ids {
            [object(rng), object(rng), object(rng)]
        } else {
            [OBJECT_NONE; 3]
        });
    }
    model
}

fn random_case(seed: u64, count: usize) -> Case {
    let mut rng = seeded_rng(seed);
    let model = random_rows(&mut rng, count, true);
    let first = random_rows(&mut rng, count, false);
    let second = random_rows(&mut rng, count, false);
    let mut stats = DensifyStats::default();
    for _ in 0..count {
        let visible = 1u32 << rng.random_range(0..4);
        // Mean gradients around the 0.0007 threshold, on a grid of exact binary fractions.
        let mean = f32::from(rng.random_range(0u16..512)) / 262_144.0;
        stats.gradient_sums.push(mean * visible as f32);
        stats.visible_counts.push(visible);
        stats.max_radii.push(rng.random_range(0.0..0.3));
    }
    Case {
        model,
        first,
        second,
        stats,
    }
}

fn parameter_buffers(
    ctx: &GpuContext,
    label: &str,
    rows: &GaussianModel,
) -> GaussianParameterBuffers {
    let buffers = GaussianParameterBuffers::new(ctx, label, rows.len()).expect("moment buffers");
    buffers.write(ctx, rows).expect("moments written");
    buffers
}

/// Runs both implementations and checks they agree; returns the GPU's summary.
fn check(
    ctx: &GpuContext,
    case: &Case,
    config: &DensifyConfig,
    guard: Option<&dyn PruneGuard>,
    max_new: Option<usize>,
) -> DensifySummary {
    let mut cpu_rng = seeded_rng(99);
    let plan = plan_densification(
        &case.model,
        &case.stats,
        config,
        EXTENT,
        guard,
        max_new,
        &mut cpu_rng,
    );
    let expected = plan.apply(&case.model, config.split_children);
    let expected_first = plan.gather(&case.first.opacity_logits, |_| 0.0);
    let expected_second_sh = plan.gather(&case.second.sh_coefficients, |_| Default::default());
    let expected_first_means = plan.gather(&case.first.means, |_| [0.0; 3]);

    let count = case.model.len();
    let gaussians = GpuGaussians::upload(ctx, &case.model, count).expect("model uploaded");
    let first = parameter_buffers(ctx, "m", &case.first);
    let second = parameter_buffers(ctx, "v", &case.second);
    let gradient_sums = storage_buffer(ctx, "sums", &case.stats.gradient_sums);
    let visible_counts = storage_buffer(ctx, "visible", &case.stats.visible_counts);
    let max_radii = storage_buffer(ctx, "radii", &case.stats.max_radii);
    let input = DensifyInput {
        gaussians: &gaussians,
        first_moments: &first,
        second_moments: &second,
        stats: StatBuffers {
            gradient_sums: &gradient_sums,
            visible_counts: &visible_counts,
            max_radii: &max_radii,
        },
    };
    let request = DensifyRequest {
        config,
        scene_extent: EXTENT,
        guard,
        max_new,
        seed: seeded_rng(99).random(),
    };
    let mut densifier = GpuDensifier::new(ctx).expect("kernels");
    let densified = densifier
        .densify(ctx, &input, &request, |needed| needed + 7)
        .expect("densified");
    let summary = densified.summary;
    assert_eq!(
        (
            summary.count,
            summary.cloned,
            summary.split,
            summary.pruned,
            summary.spared
        ),
        (
            expected.len(),
            plan.cloned,
            plan.split,
            plan.pruned,
            plan.spared
        ),
        "counts"
    );
    let capacity = densified.gaussians.capacity();
    assert!(capacity >= summary.count);
    if summary.count > count {
        assert_eq!(capacity, summary.count + 7, "grown by the caller's rule");
    }

    let model = densified.gaussians.download(ctx).expect("model read back");
    assert_eq!(model.object_ids, expected.object_ids, "object ids");
    assert_eq!(model.opacity_logits, expected.opacity_logits, "opacities");
    assert_eq!(model.rotations, expected.rotations, "rotations");
    assert_eq!(model.sh_coefficients, expected.sh_coefficients, "SH");
    assert_eq!(model.log_scales, expected.log_scales, "log scales");
    for (row, (got, want)) in model.means.iter().zip(&expected.means).enumerate() {
        let scale = expected.log_scales[row]
            .iter()
            .copied()
            .fold(f32::MIN, f32::max)
            .exp();
        for axis in 0..3 {
            let error = (got[axis] - want[axis]).abs();
            assert!(
                error <= 1e-5 * (1.0 + scale) + 1e-6 * want[axis].abs(),
                "mean of row {row}: {got:?} against {want:?}"
            );
        }
    }
    let first_back = densified
        .first_moments
        .download(ctx, summary.count)
        .expect("m");
    let second_back = densified
        .second_moments
        .download(ctx, summary.count)
        .expect("v");
    assert_eq!(
        first_back.opacity_logits, expected_first,
        "first moments (opacity)"
    );
    assert_eq!(
        first_back.means, expected_first_means,
        "first moments (means)"
    );
    assert_eq!(
        second_back.sh_coefficients, expected_second_sh,
        "second moments (SH)"
    );
    summary
}

fn pruning_config() -> DensifyConfig {
    DensifyConfig {
        max_screen_radius_fraction: Some(0.25),
        max_world_scale_fraction: Some(0.1),
        ..DensifyConfig::default()
    }
}

#[test]
fn gpu_densification_matches_the_cpu_plan_without_a_bound() {
    let Some(ctx) = gpu_context() else { return };
    let case = random_case(1, 3000);
    let summary = check(ctx, &case, &DensifyConfig::default(), None, None);
    assert!(summary.cloned > 100 && summary.split > 100, "{summary:?}");
    assert!(summary.pruned > 100, "{summary:?}");
    let summary = check(ctx, &case, &pruning_config(), None, None);
    assert!(summary.pruned > 1000, "oversized pruning ran: {summary:?}");
}

#[test]
fn gpu_densification_matches_the_cpu_plan_under_a_growth_bound() {
    let Some(ctx) = gpu_context() else { return };
    let case = random_case(2, 5000);
    let unbounded = check(ctx, &case, &DensifyConfig::default(), None, None);
    let grown = unbounded.cloned + unbounded.split;
    for room in [0, 1, grown / 3, grown - 1, grown, grown + 50] {
        let summary = check(ctx, &case, &DensifyConfig::default(), None, Some(room));
        assert_eq!(
            summary.cloned + summary.split,
            grown.min(room),
            "room {room}"
        );
    }
    // Three children a split: splits add two, so the prefix rule stops short of the room.
    let config = DensifyConfig {
        split_children: 3,
        ..DensifyConfig::default()
    };
    check(ctx, &case, &config, None, Some(grown / 2));
}

#[test]
fn gpu_densification_matches_the_cpu_plan_with_an_object_floor() {
    let Some(ctx) = gpu_context() else { return };
    let case = random_case(3, 4000);
    let floor = ObjectFloor {
        floors: [400, 300, 0],
    };
    let summary = check(ctx, &case, &pruning_config(), Some(&floor), Some(200));
    assert!(summary.spared > 0, "the floor spared some: {summary:?}");
}

#[test]
fn gpu_densification_handles_everything_pruned_and_tiny_models() {
    let Some(ctx) = gpu_context() else { return };
    let mut case = random_case(4, 40);
    case.model.opacity_logits.iter_mut().for_each(|o| *o = -9.0);
    let summary = check(ctx, &case, &DensifyConfig::default(), None, None);
    assert_eq!(summary.count, 0);
    let case = random_case(5, 1);
    check(ctx, &case, &DensifyConfig::default(), None, Some(1));
}

#[test]
fn gpu_opacity_reset_matches_the_cpu_reset() {
    let Some(ctx) = gpu_context() else { return };
    let case = random_case(6, 1000);
    let gaussians = GpuGaussians::upload(ctx, &case.model, 1000).expect("model uploaded");
    let first = parameter_buffers(ctx, "m", &case.first);
    let second = parameter_buffers(ctx, "v", &case.second);
    let densifier = GpuDensifier::new(ctx).expect("kernels");
    densifier.reset_opacity(ctx, &gaussians, &first, &second, 0.01);
    let mut expected = case.model.opacity_logits.clone();
    reset_opacity_logits(&mut expected, 0.01);
    let model = gaussians.download(ctx).expect("read back");
    assert_eq!(model.opacity_logits, expected);
    assert_eq!(model.means, case.model.means, "only opacities change");
    let first_back = first.download(ctx, 1000).expect("m");
    assert!(first_back.opacity_logits.iter().all(|&m| m == 0.0));
    assert_eq!(first_back.means, case.first.means);
    let second_back = second.download(ctx, 1000).expect("v");
    assert!(second_back.opacity_logits.iter().all(|&v| v == 0.0));
}
