//! GPU renderer against the CPU reference (f64): images, gradients, finite differences, object
//! filter, background, empty and fully culled scenes, gradient accumulation, capacity growth.

mod gpu_support;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use segsplat_engine::reference::scenes::{
    edge_case_scene, random_scene, test_camera, turned_around, two_object_scene,
};
use segsplat_engine::reference::{
    ReferenceGaussians, ReferenceGrads, parameter_name, render_backward, render_forward,
};
use segsplat_engine::render::{RasterVariant, Renderer};
use segsplat_engine::{
    GaussianModel, GpuGaussianGrads, GpuGaussians, ObjectFilter, RenderCamera, RenderSettings,
};
use segsplat_gpu::GpuContext;
use segsplat_scene::Level;
use wgpu::util::DeviceExt;

fn context() -> Option<GpuContext> {
    gpu_support::shared_gpu_context()
}

fn render_gpu(
    ctx: &GpuContext,
    renderer: &mut Renderer,
    model: &GaussianModel,
    camera: &RenderCamera,
    settings: &RenderSettings,
) -> Vec<[f32; 4]> {
    let gaussians = GpuGaussians::upload(ctx, model, model.len().max(1)).unwrap();
    let output = renderer
        .render_checked(ctx, &gaussians, camera, settings)
        .unwrap();
    output.read_image(ctx).unwrap()
}

fn max_image_error(gpu: &[[f32; 4]], cpu: &[[f64; 4]]) -> f64 {
    gpu.iter()
        .zip(cpu)
        .flat_map(|(g, c)| (0..4).map(move |k| (g[k] as f64 - c[k]).abs()))
        .fold(0.0, f64::max)
}

fn random_weights(seed: u64, pixels: usize) -> Vec<[f32; 4]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..pixels)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect()
}

/// GPU gradients of sum(weights * image), as (parameters, mean2d_abs), after `renders` backward
/// passes accumulated into one gradient buffer.
fn gpu_gradients(
    ctx: &GpuContext,
    model: &GaussianModel,
    camera: &RenderCamera,
    settings: &RenderSettings,
    weights: &[[f32; 4]],
    renders: usize,
) -> (GaussianModel, Vec<[f32; 2]>) {
    let variant = RasterVariant::for_adapter(ctx);
    gpu_gradients_with(ctx, variant, model, camera, settings, weights, renders)
}

/// [`gpu_gradients`] through the given rasterize kernels.
fn gpu_gradients_with(
    ctx: &GpuContext,
    variant: RasterVariant,
    model: &GaussianModel,
    camera: &RenderCamera,
    settings: &RenderSettings,
    weights: &[[f32; 4]],
    renders: usize,
) -> (GaussianModel, Vec<[f32; 2]>) {
    let mut renderer = Renderer::with_variant(ctx, variant).unwrap();
    let gaussians = GpuGaussians::upload(ctx, model, model.len()).unwrap();
    let mut grads = GpuGaussianGrads::new(ctx, model.len()).unwrap();
    let grad_image = ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("grad image"),
            contents: bytemuck::cast_slice(weights),
            usage: wgpu::BufferUsages::STORAGE,
        });
    let mut encoder = segsplat_gpu::Encoder::new(ctx, "test");
    grads.encode_zero(&mut encoder);
    for _ in 0..renders {
        let output = renderer
            .forward(ctx, &mut encoder, &gaussians, camera, settings)
            .unwrap();
        renderer
            .backward(
                ctx,
                &mut encoder,
                &gaussians,
                &output,
                &grad_image,
                &mut grads,
            )
            .unwrap();
    }
    ctx.submit(encoder.finish());
    assert!(!renderer.sync_capacity(ctx).unwrap().overflowed);
    grads.download(ctx, model.len()).unwrap()
}

fn reference_gradients(
    model: &GaussianModel,
    camera: &RenderCamera,
    settings: &RenderSettings,
    weights: &[[f32; 4]],
) -> ReferenceGrads {
    let gaussians = ReferenceGaussians::from_model(model);
    let forward = render_forward(&gaussians, camera, settings);
    let weights: Vec<[f64; 4]> = weights.iter().map(|w| w.map(f64::from)).collect();
    render_backward(&gaussians, &forward, &weights)
}

fn flatten_gpu(model: &GaussianModel, index: usize) -> Vec<f64> {
    ReferenceGaussians::from_model(model).parameters(index)
}

/// Largest |gpu - cpu| over all parameters, scaled by the largest |cpu| of the same Gaussian
/// parameter group, and the absolute-gradient statistic likewise.
fn compare_gradients(
    gpu: &(GaussianModel, Vec<[f32; 2]>),
    cpu: &ReferenceGrads,
    tolerance: f64,
) -> f64 {
    let count = cpu.parameters.len();
    let mut worst: f64 = 0.0;
    for index in 0..count {
        let g = flatten_gpu(&gpu.0, index);
        let c = cpu.parameters.parameters(index);
        let scale = c.iter().fold(1e-3f64, |m, v| m.max(v.abs()));
        for slot in 0..g.len() {
            let error = (g[slot] - c[slot]).abs() / scale;
            worst = worst.max(error);
            assert!(
                error <= tolerance,
                "gaussian {index} {}: gpu {} cpu {} (scale {scale})",
                parameter_name(slot),
                g[slot],
                c[slot]
            );
        }
        for axis in 0..2 {
            let (g, c) = (gpu.1[index][axis] as f64, cpu.mean2d_abs[index][axis]);
            let error = (g - c).abs() / c.abs().max(1e-3);
            assert!(
                error <= tolerance,
                "gaussian {index} mean2d_abs[{axis}]: gpu {g} cpu {c}"
            );
        }
    }
    worst
}

fn settings_with_background() -> RenderSettings {
    RenderSettings {
        background: [0.1, 0.4, 0.8],
        ..RenderSettings::default()
    }
}

#[test]
fn gpu_forward_matches_reference() {
    let Some(ctx) = context() else { return };
    let mut renderer = Renderer::new(&ctx).unwrap();
    for (seed, sh_degree) in [(11u64, 3u32), (12, 0), (13, 2)] {
        let camera = test_camera(40, 36);
        let model = edge_case_scene(seed, 40, &camera);
        let settings = RenderSettings {
            sh_degree,
            ..settings_with_background()
        };
        let gpu = render_gpu(&ctx, &mut renderer, &model, &camera, &settings);
        let cpu = render_forward(&ReferenceGaussians::from_model(&model), &camera, &settings);
        let error = max_image_error(&gpu, &cpu.image);
        println!("seed {seed} degree {sh_degree}: max abs image error {error:e}");
        assert!(error < 2e-4, "max abs error {error}");
        assert!(cpu.image.iter().any(|p| p[3] > 0.9), "scene is not empty");
    }
}

#[test]
fn gpu_gradients_match_reference_and_accumulate() {
    let Some(ctx) = context() else { return };
    let camera = test_camera(40, 36);
    let model = edge_case_scene(21, 12, &camera);
    let settings = settings_with_background();
    let weights = random_weights(22, camera.pixel_count());
    let cpu = reference_gradients(&model, &camera, &settings, &weights);
    let gpu = gpu_gradients(&ctx, &model, &camera, &settings, &weights, 1);
    let worst = compare_gradients(&gpu, &cpu, 2e-3);
    println!("worst scaled gradient error {worst:e}");
    // Two renders accumulate into the same buffers: twice the gradient.
    let doubled = gpu_gradients(&ctx, &model, &camera, &settings, &weights, 2);
    let mut twice = cpu.clone();
    for index in 0..model.len() {
        for value in twice.parameters.parameters_mut(index) {
            *value *= 2.0;
        }
        twice.mean2d_abs[index] = twice.mean2d_abs[index].map(|v| 2.0 * v);
    }
    compare_gradients(&doubled, &twice, 2e-3);
}

#[test]
fn gpu_gradients_match_finite_differences() {
    let Some(ctx) = context() else { return };
    let camera = test_camera(32, 32);
    let model = edge_case_scene(31, 4, &camera);
    let settings = RenderSettings {
        sh_degree: 2,
        ..settings_with_background()
    };
    let weights = random_weights(32, camera.pixel_count());
    let gpu = gpu_gradients(&ctx, &model, &camera, &settings, &weights, 1);
    let gaussians = ReferenceGaussians::from_model(&model);
    let weights64: Vec<[f64; 4]> = weights.iter().map(|w| w.map(f64::from)).collect();
    let loss = |g: &ReferenceGaussians| -> (f64, Vec<Vec<u32>>) {
        let forward = render_forward(g, &camera, &settings);
        let value = forward
            .image
            .iter()
            .zip(&weights64)
            .map(|(p, w)| (0..4).map(|c| p[c] * w[c]).sum::<f64>())
            .sum();
        (value, forward.contributors)
    };
    let mut checked = 0;
    for index in 0..gaussians.len() {
        let analytic = flatten_gpu(&gpu.0, index);
        let scale = analytic.iter().fold(1e-3f64, |m, v| m.max(v.abs()));
        for (slot, &gpu_value) in analytic.iter().enumerate() {
            let eps = 1e-6;
            let mut plus = gaussians.clone();
            *plus.parameters_mut(index)[slot] += eps;
            let mut minus = gaussians.clone();
            *minus.parameters_mut(index)[slot] -= eps;
            let (lp, cp) = loss(&plus);
            let (lm, cm) = loss(&minus);
            if cp != cm {
                continue; // a fragment crossed a threshold: no derivative here
            }
            let numeric = (lp - lm) / (2.0 * eps);
            let error = (numeric - gpu_value).abs() / scale;
            assert!(
                error < 2e-3,
                "gaussian {index} {}: gpu {gpu_value} numeric {numeric}",
                parameter_name(slot),
            );
            checked += 1;
        }
    }
    assert!(checked > 200, "{checked} derivatives checked");
}

#[test]
fn gpu_object_filter_renders_exactly_that_object() {
    let Some(ctx) = context() else { return };
    let mut renderer = Renderer::new(&ctx).unwrap();
    let camera = test_camera(48, 32);
    let model = two_object_scene(41, 6, &camera);
    let reference = ReferenceGaussians::from_model(&model);
    for id in [1u32, 2] {
        let settings = RenderSettings {
            filter: ObjectFilter::Object {
                level: Level::Large,
                id,
            },
            ..RenderSettings::default()
        };
        let gpu = render_gpu(&ctx, &mut renderer, &model, &camera, &settings);
        let cpu = render_forward(&reference, &camera, &settings);
        assert!(max_image_error(&gpu, &cpu.image) < 2e-4);
        let (own, other) = if id == 1 {
            (0..20, 28..48)
        } else {
            (28..48, 0..20)
        };
        let alpha = |columns: std::ops::Range<u32>| -> f32 {
            (0..camera.height)
                .flat_map(|y| {
                    columns
                        .clone()
                        .map(move |x| (y * camera.width + x) as usize)
                })
                .map(|i| gpu[i][3])
                .sum()
        };
        assert!(alpha(own) > 10.0, "object {id} is drawn");
        assert_eq!(alpha(other), 0.0, "the other object is absent");
    }
    // A filter for an id no Gaussian has draws nothing.
    let settings = RenderSettings {
        filter: ObjectFilter::Object {
            level: Level::Small,
            id: 7,
        },
        ..RenderSettings::default()
    };
    let gpu = render_gpu(&ctx, &mut renderer, &model, &camera, &settings);
    assert!(gpu.iter().all(|p| *p == [0.0; 4]));
}

#[test]
fn gpu_empty_and_culled_scenes_show_background() {
    let Some(ctx) = context() else { return };
    let mut renderer = Renderer::new(&ctx).unwrap();
    let camera = test_camera(20, 17);
    let settings = settings_with_background();
    let expected = [0.1, 0.4, 0.8, 0.0];
    let empty = render_gpu(
        &ctx,
        &mut renderer,
        &GaussianModel::default(),
        &camera,
        &settings,
    );
    assert_eq!(empty.len(), 20 * 17);
    assert!(empty.iter().all(|p| *p == expected), "empty scene");
    let model = random_scene(51, 30, &camera);
    let culled = render_gpu(
        &ctx,
        &mut renderer,
        &model,
        &turned_around(&camera),
        &settings,
    );
    assert!(culled.iter().all(|p| *p == expected), "everything culled");
    // The same scene seen the right way round is not background.
    let visible = render_gpu(&ctx, &mut renderer, &model, &camera, &settings);
    assert!(visible.iter().any(|p| p[3] > 0.5));
}

/// Two forward renders, submitted and not read: what the training loop's steps leave for its
/// next capacity read.
fn render_twice(
    ctx: &GpuContext,
    renderer: &mut Renderer,
    gaussians: &GpuGaussians,
    camera: &RenderCamera,
) {
    for _ in 0..2 {
        let mut encoder = segsplat_gpu::Encoder::new(ctx, "test");
        let output = renderer
            .forward(
                ctx,
                &mut encoder,
                gaussians,
                camera,
                &RenderSettings::default(),
            )
            .unwrap();
        ctx.submit(encoder.finish());
        drop(output);
    }
}

#[test]
fn gpu_intersection_overflow_is_reported_and_grown() {
    let Some(ctx) = context() else { return };
    let mut renderer = Renderer::new(&ctx).unwrap();
    let camera = test_camera(64, 48);
    // 300 Gaussians each covering every one of the 12 tiles: 3600 intersections, more than the
    // initial 8 per Gaussian.
    let mut model = random_scene(61, 300, &camera);
    for (mean, log_scale) in model.means.iter().zip(model.log_scales.iter_mut()) {
        *log_scale = [(40.0 * mean[2] / camera.fx).ln(); 3];
    }
    let settings = RenderSettings::default();
    let gaussians = GpuGaussians::upload(&ctx, &model, model.len()).unwrap();
    renderer.set_intersection_capacity(1);
    let mut encoder = segsplat_gpu::Encoder::new(&ctx, "test");
    let output = renderer
        .forward(&ctx, &mut encoder, &gaussians, &camera, &settings)
        .unwrap();
    ctx.submit(encoder.finish());
    let (needed, held) = output.read_intersection_count(&ctx).unwrap();
    drop(output);
    assert!(
        needed > held,
        "test scene must overflow: {needed} <= {held}"
    );
    let report = renderer.sync_capacity(&ctx).unwrap();
    assert!(report.overflowed);
    assert_eq!(report.peak_intersections, needed);
    assert!(report.capacity >= needed);
    // The clamped render was used (nothing rendered it again): counted.
    assert_eq!(report.clamped_renders, 1);
    assert_eq!(renderer.clamped_renders(), 1);
    renderer.set_intersection_capacity(1);
    let output = renderer
        .render_checked(&ctx, &gaussians, &camera, &settings)
        .unwrap();
    let gpu = output.read_image(&ctx).unwrap();
    let cpu = render_forward(&ReferenceGaussians::from_model(&model), &camera, &settings);
    assert!(max_image_error(&gpu, &cpu.image) < 2e-4);
    // render_checked's clamped first attempt was rendered again, so it is not a used render;
    // two renders that fit add nothing either.
    assert_eq!(renderer.clamped_renders(), 1);
    render_twice(&ctx, &mut renderer, &gaussians, &camera);
    let report = renderer.sync_capacity(&ctx).unwrap();
    assert!(!report.overflowed);
    assert_eq!(report.clamped_renders, 0);
    // Two clamped renders read without waiting, as the training loop reads them (a renderer of
    // its own: the first one's pool holds workspaces that fit).
    let mut renderer = Renderer::new(&ctx).unwrap();
    renderer.set_intersection_capacity(1);
    render_twice(&ctx, &mut renderer, &gaussians, &camera);
    let mut encoder = segsplat_gpu::Encoder::new(&ctx, "test");
    let slot = renderer.request_capacity_check(&mut encoder).unwrap();
    ctx.submit(encoder.finish());
    renderer.capacity_check_submitted(slot);
    ctx.wait_idle().unwrap();
    renderer.apply_capacity_check(&ctx).unwrap();
    assert_eq!(renderer.clamped_renders(), 2);
    assert!(renderer.intersection_capacity() >= needed);
    // A sync after the deferred read finds no new clamped render: the count is not read twice.
    assert_eq!(renderer.sync_capacity(&ctx).unwrap().clamped_renders, 0);
    assert_eq!(renderer.clamped_renders(), 2);
    // Two deferred copies delivered together, the big render's first: `DeferredRead` hands back
    // only the newer, which must still hold the big render's peak.
    let mut renderer = Renderer::new(&ctx).unwrap();
    renderer.set_intersection_capacity(needed / 2);
    let few = random_scene(62, 4, &camera);
    let few = GpuGaussians::upload(&ctx, &few, few.len()).unwrap();
    for scene in [&gaussians, &few] {
        let mut encoder = segsplat_gpu::Encoder::new(&ctx, "test");
        let output = renderer
            .forward(&ctx, &mut encoder, scene, &camera, &settings)
            .unwrap();
        drop(output);
        let slot = renderer.request_capacity_check(&mut encoder).unwrap();
        ctx.submit(encoder.finish());
        renderer.capacity_check_submitted(slot);
    }
    ctx.wait_idle().unwrap();
    renderer.apply_capacity_check(&ctx).unwrap();
    assert!(
        renderer.intersection_capacity() >= needed,
        "the big render's peak was lost: capacity {} < {needed}",
        renderer.intersection_capacity()
    );
    assert_eq!(renderer.clamped_renders(), 1);
}

#[test]
fn gpu_gradients_with_compare_and_swap_atomics_match_reference() {
    let Some(mut ctx) = context() else { return };
    // Kernels pick the CAS loop when the device reports no native f32 atomics.
    ctx.features.remove(wgpu::Features::SHADER_FLOAT32_ATOMIC);
    let camera = test_camera(40, 36);
    let model = edge_case_scene(71, 12, &camera);
    let settings = settings_with_background();
    let weights = random_weights(72, camera.pixel_count());
    let cpu = reference_gradients(&model, &camera, &settings, &weights);
    let gpu = gpu_gradients(&ctx, &model, &camera, &settings, &weights, 1);
    compare_gradients(&gpu, &cpu, 2e-3);
}

#[test]
fn gpu_gradients_summed_over_subgroups_match_reference() {
    let Some(mut ctx) = context() else { return };
    if !ctx.has_subgroups() {
        eprintln!("skipping: the adapter has no subgroups");
        return;
    }
    // Hardware adapters sum each pixel's gradients over the subgroup by subgroupAdd before the
    // atomics; software ones walk columns (what the other tests check on lavapipe). Pretend to be
    // hardware.
    ctx.report.is_software = false;
    let camera = test_camera(40, 36);
    let model = edge_case_scene(73, 12, &camera);
    let settings = settings_with_background();
    let weights = random_weights(74, camera.pixel_count());
    let cpu = reference_gradients(&model, &camera, &settings, &weights);
    let gpu = gpu_gradients(&ctx, &model, &camera, &settings, &weights, 1);
    compare_gradients(&gpu, &cpu, 2e-3);
}

/// Checks every rasterize variant the adapter can run, whatever it picks for itself (one pixel
/// per invocation with and without subgroup sums, columns walked a splat per lane), against the
/// reference's image and gradients of `model`.
fn assert_every_variant_matches_reference(
    ctx: &GpuContext,
    model: &GaussianModel,
    camera: &RenderCamera,
    seed: u64,
) {
    let settings = settings_with_background();
    let weights = random_weights(seed, camera.pixel_count());
    let cpu_image = render_forward(&ReferenceGaussians::from_model(model), camera, &settings);
    let cpu = reference_gradients(model, camera, &settings, &weights);
    for variant in RasterVariant::supported(ctx) {
        let mut renderer = Renderer::with_variant(ctx, variant).unwrap();
        let image = render_gpu(ctx, &mut renderer, model, camera, &settings);
        let error = max_image_error(&image, &cpu_image.image);
        assert!(error < 2e-4, "{variant:?}: max abs image error {error}");
        let gpu = gpu_gradients_with(ctx, variant, model, camera, &settings, &weights, 1);
        let worst = compare_gradients(&gpu, &cpu, 2e-3);
        println!("{variant:?}: image error {error:.1e}, gradient error {worst:.1e}");
    }
}

#[test]
fn every_raster_variant_matches_reference() {
    let Some(ctx) = context() else { return };
    // 40 x 36: partial tiles on both edges.
    let camera = test_camera(40, 36);
    let model = edge_case_scene(75, 24, &camera);
    assert_every_variant_matches_reference(&ctx, &model, &camera, 76);
}

/// Tiles listing hundreds of splats, most pixels saturating before the end of their list: every
/// variant walks many batches or lane chunks, stops early and culls splats per block.
#[test]
fn every_raster_variant_matches_reference_on_dense_tiles() {
    let Some(ctx) = context() else { return };
    let camera = test_camera(48, 40);
    let model = random_scene(77, 400, &camera);
    let image = render_forward(
        &ReferenceGaussians::from_model(&model),
        &camera,
        &settings_with_background(),
    )
    .image;
    let saturated = image.iter().filter(|p| p[3] > 0.999).count();
    assert!(
        saturated * 2 > image.len(),
        "test scene must saturate most pixels: {saturated}"
    );
    assert_every_variant_matches_reference(&ctx, &model, &camera, 78);
}

/// Tiles whose 16 x 16 square the footprint ellipse `sigma <= sigma_max` reaches into, found per
/// tile from the least sigma over the square (an independent route to the GPU's row-by-row one).
fn footprint_tile_count(
    mean2d: [f64; 2],
    conic: [f64; 3],
    sigma_max: f64,
    tiles: [u32; 2],
) -> usize {
    let sigma =
        |dx: f64, dy: f64| 0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) + conic[1] * dx * dy;
    let tile = segsplat_engine::TILE_SIZE as f64;
    let mut count = 0;
    for ty in 0..tiles[1] {
        for tx in 0..tiles[0] {
            let lo = [tx as f64 * tile - mean2d[0], ty as f64 * tile - mean2d[1]];
            let hi = [lo[0] + tile, lo[1] + tile];
            let inside = lo[0] <= 0.0 && hi[0] >= 0.0 && lo[1] <= 0.0 && hi[1] >= 0.0;
            let least = [lo[0], hi[0]]
                .map(|x| sigma(x, (-conic[1] * x / conic[2]).clamp(lo[1], hi[1])))
                .into_iter()
                .chain(
                    [lo[1], hi[1]]
                        .map(|y| sigma((-conic[1] * y / conic[0]).clamp(lo[0], hi[0]), y)),
                )
                .fold(f64::INFINITY, f64::min);
            if inside || least <= sigma_max {
                count += 1;
            }
        }
    }
    count
}

#[test]
fn gpu_tile_lists_hold_the_tiles_each_footprint_touches() {
    let Some(ctx) = context() else { return };
    let mut renderer = Renderer::new(&ctx).unwrap();
    let camera = test_camera(96, 80);
    let settings = RenderSettings::default();
    // Faint, thin and opaque splats: a fixed 3-sigma square would list many more tiles.
    let mut model = edge_case_scene(91, 150, &camera);
    let mut rng = ChaCha8Rng::seed_from_u64(92);
    for logit in model.opacity_logits.iter_mut() {
        *logit = rng.random_range(-5.0..4.0);
    }
    let reference = render_forward(&ReferenceGaussians::from_model(&model), &camera, &settings);
    // The kernels widen sigma_max by 0.01 so no passing fragment falls outside the lists.
    let expected: usize = reference
        .projected
        .iter()
        .flatten()
        .map(|p| {
            let sigma_max = (p.opacity / segsplat_engine::ALPHA_MIN as f64).ln() + 0.01;
            footprint_tile_count(p.mean2d.to_array(), p.conic, sigma_max, camera.tile_grid())
        })
        .sum();
    let square: usize = reference
        .projected
        .iter()
        .flatten()
        .map(|p| {
            let tile = segsplat_engine::TILE_SIZE as f64;
            let span = |centre: f64, tiles: u32| {
                let lo = ((centre - p.radius) / tile)
                    .floor()
                    .clamp(0.0, tiles as f64);
                let hi = ((centre + p.radius) / tile).ceil().clamp(0.0, tiles as f64);
                (hi - lo) as usize
            };
            span(p.mean2d.x, camera.tile_grid()[0]) * span(p.mean2d.y, camera.tile_grid()[1])
        })
        .sum();
    let gaussians = GpuGaussians::upload(&ctx, &model, model.len()).unwrap();
    let output = renderer
        .render_checked(&ctx, &gaussians, &camera, &settings)
        .unwrap();
    let (listed, _) = output.read_intersection_count(&ctx).unwrap();
    let image = output.read_image(&ctx).unwrap();
    println!("intersections: {listed} listed, {expected} expected, {square} with 3-sigma squares");
    assert_eq!(listed as usize, expected);
    assert!((listed as usize) * 4 < square * 3, "{listed} vs {square}");
    assert!(max_image_error(&image, &reference.image) < 2e-4);
}
