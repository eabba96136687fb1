//! The deformation field's WGSL kernels against the f64 reference (`splat::deform::reference` and
//! `warp`, themselves checked against finite differences in their unit tests), and the GPU
//! gradient against central differences of the GPU forward.
//!
//! Shapes are small but exercise everything the default 8 x 256 does: several 64-wide GEMM tiles
//! (width 80), the skip concatenation, a head narrower than a tile, split-K weight gradients and
//! more Gaussians than one chunk (so the backward recomputes chunks).
//! Tolerances: forward outputs within 2e-5 relative to their scale; weight gradients within 1e-4
//! of the largest gradient of their layer (f32 sums over 150 Gaussians).
//!
//! Every GEMM kernel the adapter can run is checked (`GemmKernel::supported`): the tiled one
//! hardware GPUs use, the row-per-invocation one, and the subgroup-broadcast one software
//! adapters with 8-lane subgroups use.
//!
//! The tests share a context whose uniform ring holds 32 kernel parameters
//! (`small_ring_gpu_context`), so while one test records, the others go round the ring many
//! times: on the H200 (stop 54) this binary's parallel tests got wrong products because another
//! thread's submission freed slots a recording still needed.

mod gpu_support;

use gpu_support::{new_encoder, seeded_rng, small_ring_gpu_context, submit};
use rand::Rng;
use segsplat_engine::deform::reference;
use segsplat_engine::deform::warp::{Pose, warp, warp_backward};
use segsplat_engine::deform::{
    DeformationField, DeformedGeometry, FieldShape, GemmKernel, WarpKind, measure_matmul,
};
use segsplat_engine::{GaussianModel, GpuGaussianGrads, GpuGaussians, OBJECT_NONE};
use segsplat_gpu::GpuContext;

const COUNT: usize = 150;
const CHUNK: usize = 64;
const TIME: f32 = 0.37;

fn shape(warp: WarpKind) -> FieldShape {
    FieldShape {
        depth: 4,
        width: 80,
        skip_after: 2,
        position_frequencies: 4,
        time_frequencies: 3,
        warp,
    }
}

fn random_model(seed: u64) -> GaussianModel {
    let mut rng = seeded_rng(seed);
    let mut model = GaussianModel::default();
    for _ in 0..COUNT {
        let mut v = || rng.random_range(-1.0f32..1.0);
        model.push_simple(
            [v(), v(), v()],
            [v() - 2.0, v() - 2.0, v() - 2.0],
            [v() + 1.5, v(), v(), v()],
            v(),
            [0.5; 3],
            [OBJECT_NONE; 3],
        );
    }
    model
}

fn pose_of(model: &GaussianModel, i: usize) -> Pose {
    Pose {
        mean: model.means[i].map(f64::from),
        log_scale: model.log_scales[i].map(f64::from),
        rotation: model.rotations[i].map(f64::from),
    }
}

/// Random weights in every layer (the head too, so every layer carries a gradient).
fn parameters(shape: &FieldShape, seed: u64) -> Vec<f32> {
    let mut rng = seeded_rng(seed);
    shape.random_parameters(&mut rng)
}

struct Setup {
    field: DeformationField,
    canonical: GpuGaussians,
    deformed: DeformedGeometry,
    model: GaussianModel,
    params: Vec<f32>,
}

fn setup(ctx: &GpuContext, warp_kind: WarpKind, gemm: GemmKernel) -> Setup {
    let shape = shape(warp_kind);
    let params = parameters(&shape, 11);
    let model = random_model(5);
    Setup {
        field: DeformationField::with_gemm(ctx, shape, &params, CHUNK, gemm).expect("field"),
        canonical: GpuGaussians::upload(ctx, &model, COUNT).expect("upload"),
        deformed: DeformedGeometry::new(ctx, COUNT).expect("geometry"),
        model,
        params,
    }
}

fn read3(ctx: &GpuContext, buffer: &wgpu::Buffer) -> Vec<f32> {
    ctx.read_vec::<f32>(buffer).expect("read")
}

/// The largest error of the GPU's deformed geometry against the reference, the largest move the
/// reference makes, and how many Gaussians of each chunk are off by more than `tolerance`.
fn forward_errors(
    s: &Setup,
    warp_kind: WarpKind,
    deformed: [&[f32]; 3],
    tolerance: f64,
) -> (f64, f64, Vec<usize>) {
    let [means, rotations, log_scales] = deformed;
    let params64: Vec<f64> = s.params.iter().map(|&p| f64::from(p)).collect();
    let shape = *s.field.shape();
    let mut worst: f64 = 0.0;
    let mut moved: f64 = 0.0;
    let mut wrong_per_chunk = vec![0; COUNT.div_ceil(CHUNK)];
    for i in 0..COUNT {
        let pose = pose_of(&s.model, i);
        let acts = reference::forward(&shape, &params64, pose.mean, f64::from(TIME));
        let expected = warp(warp_kind, &pose, &acts.head);
        let mut error: f64 = 0.0;
        for k in 0..3 {
            error = error.max((f64::from(means[3 * i + k]) - expected.mean[k]).abs());
            error = error.max((f64::from(log_scales[3 * i + k]) - expected.log_scale[k]).abs());
            moved = moved.max((expected.mean[k] - pose.mean[k]).abs());
        }
        for k in 0..4 {
            error = error.max((f64::from(rotations[4 * i + k]) - expected.rotation[k]).abs());
        }
        if error >= tolerance {
            wrong_per_chunk[i / CHUNK] += 1;
        }
        worst = worst.max(error);
    }
    (worst, moved, wrong_per_chunk)
}

fn run_forward(ctx: &GpuContext, s: &mut Setup) -> [Vec<f32>; 3] {
    let mut encoder = new_encoder(ctx);
    s.field
        .encode_forward(ctx, &mut encoder, &s.canonical, &s.deformed, TIME)
        .expect("forward");
    submit(ctx, encoder);
    [
        read3(ctx, &s.deformed.means),
        read3(ctx, &s.deformed.rotations),
        read3(ctx, &s.deformed.log_scales),
    ]
}

fn check_forward(warp_kind: WarpKind, gemm: GemmKernel) {
    const TOLERANCE: f64 = 5e-5;
    let Some(ctx) = small_ring_gpu_context() else {
        return;
    };
    let mut s = setup(ctx, warp_kind, gemm);
    let [means, rotations, log_scales] = run_forward(ctx, &mut s);
    let (worst, moved, wrong) =
        forward_errors(&s, warp_kind, [&means, &rotations, &log_scales], TOLERANCE);
    println!("{warp_kind:?} {gemm:?}: max abs error {worst:.2e}, largest move {moved:.3}");
    assert!(moved > 0.05, "the field barely moves anything ({moved})");
    if worst >= TOLERANCE {
        // What tells a race from a wrong kernel on an adapter where this fails (the tiled GEMM
        // on the H200, stop 54): whether the same forward on the same buffers, run again once
        // the first is done, is wrong again and where.
        let [means, rotations, log_scales] = run_forward(ctx, &mut s);
        let (again, _, wrong_again) =
            forward_errors(&s, warp_kind, [&means, &rotations, &log_scales], TOLERANCE);
        panic!(
            "{gemm:?} GPU forward differs from the reference by {worst}; Gaussians off per chunk \
             of {CHUNK}: {wrong:?}; the same forward run again: {again} off, {wrong_again:?}"
        );
    }
}

#[test]
fn forward_matches_reference_with_translation() {
    let Some(ctx) = small_ring_gpu_context() else {
        return;
    };
    for gemm in GemmKernel::supported(ctx) {
        check_forward(WarpKind::Translation, gemm);
    }
}

#[test]
fn forward_matches_reference_with_screw_motion() {
    let Some(ctx) = small_ring_gpu_context() else {
        return;
    };
    for gemm in GemmKernel::supported(ctx) {
        check_forward(WarpKind::Screw, gemm);
    }
}

/// Upstream gradients d loss / d deformed geometry, as a render would leave them.
fn upstream(seed: u64) -> GaussianModel {
    let mut model = random_model(seed);
    for rotation in &mut model.rotations {
        rotation[0] -= 1.5;
    }
    model
}

/// Runs the field forward and back with `upstream` as d loss / d deformed geometry; returns the
/// gradient buffers (now canonical) after the GPU is done. Field gradients are in `s.field`.
fn forward_and_backward(
    ctx: &GpuContext,
    s: &mut Setup,
    upstream: &GaussianModel,
) -> GpuGaussianGrads {
    let grads = GpuGaussianGrads::new(ctx, COUNT).expect("grads");
    grads.parameters.write(ctx, upstream).expect("write grads");
    let mut encoder = new_encoder(ctx);
    s.field.encode_zero_grads(&mut encoder);
    s.field
        .encode_forward(ctx, &mut encoder, &s.canonical, &s.deformed, TIME)
        .expect("forward");
    s.field
        .encode_backward(ctx, &mut encoder, &s.canonical, &grads, TIME)
        .expect("backward");
    submit(ctx, encoder);
    grads
}

fn check_backward(warp_kind: WarpKind, gemm: GemmKernel) {
    let Some(ctx) = small_ring_gpu_context() else {
        return;
    };
    let mut s = setup(ctx, warp_kind, gemm);
    let upstream = upstream(9);
    let grads = forward_and_backward(ctx, &mut s, &upstream);
    let gpu_field_grads = s.field.read(ctx, &s.field.grads).expect("read");
    let (gpu_canonical, _) = grads.download(ctx, COUNT).expect("download");

    let shape = *s.field.shape();
    let params64: Vec<f64> = s.params.iter().map(|&p| f64::from(p)).collect();
    let mut expected_field = vec![0.0f64; params64.len()];
    let mut worst_canonical: f64 = 0.0;
    for i in 0..COUNT {
        let pose = pose_of(&s.model, i);
        let acts = reference::forward(&shape, &params64, pose.mean, f64::from(TIME));
        let grad_deformed = pose_of(&upstream, i);
        let (grad_canonical, grad_head) =
            warp_backward(warp_kind, &pose, &acts.head, &grad_deformed);
        reference::backward(&shape, &params64, &acts, &grad_head, &mut expected_field);
        for k in 0..3 {
            worst_canonical = worst_canonical
                .max((f64::from(gpu_canonical.means[i][k]) - grad_canonical.mean[k]).abs());
            worst_canonical = worst_canonical.max(
                (f64::from(gpu_canonical.log_scales[i][k]) - grad_canonical.log_scale[k]).abs(),
            );
        }
        for k in 0..4 {
            worst_canonical = worst_canonical
                .max((f64::from(gpu_canonical.rotations[i][k]) - grad_canonical.rotation[k]).abs());
        }
    }
    assert!(
        worst_canonical < 1e-4,
        "canonical gradients differ by {worst_canonical}"
    );
    for (index, layer) in shape.layers().iter().enumerate() {
        let range = layer.weight_offset..layer.bias_offset + layer.outputs;
        let scale = expected_field[range.clone()]
            .iter()
            .fold(0.0f64, |m, g| m.max(g.abs()));
        let worst = range
            .clone()
            .map(|j| (f64::from(gpu_field_grads[j]) - expected_field[j]).abs())
            .fold(0.0, f64::max);
        println!(
            "{warp_kind:?} {gemm:?} layer {index}: max error {worst:.2e} of scale {scale:.2e}"
        );
        assert!(scale > 0.0, "layer {index} got no gradient");
        assert!(
            worst <= 1e-4 * scale,
            "layer {index}: weight gradients differ by {worst} (scale {scale})"
        );
    }
}

#[test]
fn backward_matches_reference_with_translation() {
    let Some(ctx) = small_ring_gpu_context() else {
        return;
    };
    for gemm in GemmKernel::supported(ctx) {
        check_backward(WarpKind::Translation, gemm);
    }
}

#[test]
fn backward_matches_reference_with_screw_motion() {
    let Some(ctx) = small_ring_gpu_context() else {
        return;
    };
    for gemm in GemmKernel::supported(ctx) {
        check_backward(WarpKind::Screw, gemm);
    }
}

/// The objective `sum_i upstream_i . deformed_i` evaluated on the GPU.
fn gpu_objective(ctx: &GpuContext, s: &mut Setup, params: &[f32], upstream: &GaussianModel) -> f64 {
    s.field.write_parameters(ctx, params).expect("write");
    let mut encoder = new_encoder(ctx);
    s.field
        .encode_forward(ctx, &mut encoder, &s.canonical, &s.deformed, TIME)
        .expect("forward");
    submit(ctx, encoder);
    let means = read3(ctx, &s.deformed.means);
    let rotations = read3(ctx, &s.deformed.rotations);
    let log_scales = read3(ctx, &s.deformed.log_scales);
    let mut total = 0.0f64;
    for i in 0..COUNT {
        for k in 0..3 {
            total += f64::from(means[3 * i + k]) * f64::from(upstream.means[i][k]);
            total += f64::from(log_scales[3 * i + k]) * f64::from(upstream.log_scales[i][k]);
        }
        for k in 0..4 {
            total += f64::from(rotations[4 * i + k]) * f64::from(upstream.rotations[i][k]);
        }
    }
    total
}

#[test]
fn gpu_gradient_matches_central_differences_of_the_gpu_forward() {
    let Some(ctx) = small_ring_gpu_context() else {
        return;
    };
    let mut s = setup(ctx, WarpKind::Screw, GemmKernel::for_adapter(ctx));
    let upstream = upstream(9);
    forward_and_backward(ctx, &mut s, &upstream);
    let analytic = s.field.read(ctx, &s.field.grads).expect("read");
    // The parameters with the largest gradients of each layer: f32 differences resolve them.
    let layers = s.field.shape().layers();
    let base = s.params.clone();
    let h = 1e-2f32;
    let mut checked = 0;
    for layer in &layers {
        let range = layer.weight_offset..layer.bias_offset + layer.outputs;
        let mut order: Vec<usize> = range.collect();
        order.sort_by(|&a, &b| analytic[b].abs().total_cmp(&analytic[a].abs()));
        for &j in order.iter().take(3) {
            let mut plus = base.clone();
            let mut minus = base.clone();
            plus[j] += h;
            minus[j] -= h;
            let numeric = (gpu_objective(ctx, &mut s, &plus, &upstream)
                - gpu_objective(ctx, &mut s, &minus, &upstream))
                / (2.0 * f64::from(h));
            let a = f64::from(analytic[j]);
            assert!(
                (numeric - a).abs() <= 2e-2 * a.abs().max(1e-3),
                "parameter {j}: finite difference {numeric} vs analytic {a}"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 3 * layers.len());
}

/// `measure_matmul` (behind `segsplat bench-matmul` and `bench --deformation`'s `matmul`) times
/// products that are right: each of the three, for every kernel the adapter runs, matches an
/// f64 product on sampled outputs, on shapes that are no multiple of any block. Three widths: the
/// weight gradients' rows are the width, and the broadcast and row kernels size their
/// workgroups to those rows, short, middle or tall (60, 72 and 200 take one each; the widest
/// over fewer Gaussians, as the tiled kernel takes seconds for it on a software adapter).
#[test]
fn matmul_benchmark_measures_correct_products() {
    let Some(ctx) = small_ring_gpu_context() else {
        return;
    };
    for (gemm, (rows, width)) in GemmKernel::supported(ctx)
        .into_iter()
        .flat_map(|gemm| [(gemm, (1100, 60)), (gemm, (1100, 72)), (gemm, (300, 200))])
    {
        let report = measure_matmul(ctx, gemm, rows, width, 1).expect("matmul benchmark");
        assert_eq!(report.products.len(), 3);
        for product in &report.products {
            println!(
                "{gemm:?} width {width} {}: {:.2} GFLOP/s, max error {:.1e}",
                product.product, product.gflops, product.max_error
            );
            assert!(product.gflops > 0.0, "{gemm:?} {}", product.product);
            assert!(
                product.max_error < 1e-4,
                "{gemm:?} width {width} {}: error {}",
                product.product,
                product.max_error
            );
        }
        assert!(report.gflops > 0.0);
    }
}
