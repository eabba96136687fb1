//! Batched object renders (`Renderer::forward_objects` / `backward_objects_screen`) against separate
//! per-object renders (`ObjectFilter::Object`, the path before batching): the same images, and
//! the same gradients summed over the step's renders, on random scenes whose objects overlap and
//! occlude each other, for every rasterize variant the adapter runs.

mod gpu_support;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use segsplat_engine::reference::ReferenceGaussians;
use segsplat_engine::reference::parameter_name;
use segsplat_engine::reference::scenes::{random_scene, test_camera};
use segsplat_engine::render::{ObjectBatchOutput, ObjectSlot, RasterVariant, Renderer};
use segsplat_engine::{
    GaussianModel, GpuGaussianGrads, GpuGaussians, OCCUPANCY_CELL, ObjectFilter, RenderCamera,
    RenderSettings,
};
use segsplat_gpu::GpuContext;
use segsplat_scene::Level;
use wgpu::util::DeviceExt;

fn context() -> Option<GpuContext> {
    gpu_support::shared_gpu_context()
}

/// Objects at every level (random_scene gives each Gaussian ids 0..3 per level, so objects of
/// one level interleave in depth and those of different levels share Gaussians), plus an id no
/// Gaussian has.
fn slots() -> Vec<ObjectSlot> {
    [
        (Level::Small, 0),
        (Level::Small, 2),
        (Level::Middle, 1),
        (Level::Large, 0),
        (Level::Large, 2),
        (Level::Middle, 9),
    ]
    .into_iter()
    .map(|(level, id)| ObjectSlot { level, id })
    .collect()
}

fn full_settings() -> RenderSettings {
    RenderSettings {
        background: [0.1, 0.4, 0.8],
        sh_degree: 3,
        ..RenderSettings::default()
    }
}

fn object_settings(slot: &ObjectSlot) -> RenderSettings {
    RenderSettings {
        filter: slot.filter(),
        background: [0.0; 3],
        sh_degree: 3,
    }
}

fn random_weights(seed: u64, pixels: usize) -> Vec<[f32; 4]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..pixels)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect()
}

fn buffer(ctx: &GpuContext, data: &[[f32; 4]]) -> wgpu::Buffer {
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("grad image"),
            contents: bytemuck::cast_slice(data),
            usage: wgpu::BufferUsages::STORAGE,
        })
}

/// Parameter gradients and the |d mean2d| statistic, as `GpuGaussianGrads::download` gives them.
type Grads = (GaussianModel, Vec<[f32; 2]>);

struct Case {
    model: GaussianModel,
    camera: RenderCamera,
    slots: Vec<ObjectSlot>,
    /// d loss / d image of the full render, then of each slot.
    weights: Vec<Vec<[f32; 4]>>,
}

impl Case {
    fn new(seed: u64, count: usize, width: u32, height: u32) -> Self {
        let camera = test_camera(width, height);
        let slots = slots();
        let pixels = camera.pixel_count();
        let weights = (0..=slots.len() as u64)
            .map(|render| random_weights(seed * 31 + render, pixels))
            .collect();
        Self {
            model: random_scene(seed, count, &camera),
            camera,
            slots,
            weights,
        }
    }
}

/// Images of each slot and the step's gradients, rendering every object separately.
fn separate(ctx: &GpuContext, variant: RasterVariant, case: &Case) -> (Vec<Vec<[f32; 4]>>, Grads) {
    let mut renderer = Renderer::with_variant(ctx, variant).unwrap();
    // Room for every slot's intersections: these tests are about batching, not overflow.
    renderer.set_intersection_capacity(1 << 20);
    let gaussians = GpuGaussians::upload(ctx, &case.model, case.model.len()).unwrap();
    let mut grads = GpuGaussianGrads::new(ctx, case.model.len()).unwrap();
    let mut encoder = segsplat_gpu::Encoder::new(ctx, "test");
    grads.encode_zero(&mut encoder);
    let settings = std::iter::once(full_settings()).chain(case.slots.iter().map(object_settings));
    let mut outputs = Vec::new();
    for (settings, weights) in settings.zip(&case.weights) {
        let grad_image = buffer(ctx, weights);
        let output = renderer
            .forward(ctx, &mut encoder, &gaussians, &case.camera, &settings)
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
        outputs.push(output);
    }
    ctx.submit(encoder.finish());
    assert!(!renderer.sync_capacity(ctx).unwrap().overflowed);
    let images = outputs[1..]
        .iter()
        .map(|output| output.read_image(ctx).unwrap())
        .collect();
    (images, grads.download(ctx, case.model.len()).unwrap())
}

/// The same step batched as the trainer records it: the full render and its screen-space
/// backward, the object slots on top of it, then one projection backward for all.
fn batched(ctx: &GpuContext, variant: RasterVariant, case: &Case) -> (Vec<Vec<[f32; 4]>>, Grads) {
    let mut renderer = Renderer::with_variant(ctx, variant).unwrap();
    // Room for every slot's intersections: these tests are about batching, not overflow.
    renderer.set_intersection_capacity(1 << 20);
    let gaussians = GpuGaussians::upload(ctx, &case.model, case.model.len()).unwrap();
    let mut grads = GpuGaussianGrads::new(ctx, case.model.len()).unwrap();
    let mut encoder = segsplat_gpu::Encoder::new(ctx, "test");
    grads.encode_zero(&mut encoder);
    let full_grad = buffer(ctx, &case.weights[0]);
    let base = renderer
        .forward(
            ctx,
            &mut encoder,
            &gaussians,
            &case.camera,
            &full_settings(),
        )
        .unwrap();
    renderer
        .backward_screen(ctx, &mut encoder, &base, &full_grad)
        .unwrap();
    let batch = renderer
        .forward_objects(ctx, &mut encoder, &gaussians, &base, &case.slots)
        .unwrap();
    let slot_grads: Vec<[f32; 4]> = case.weights[1..].concat();
    let slot_grads = buffer(ctx, &slot_grads);
    renderer
        .backward_objects_screen(ctx, &mut encoder, &batch, &slot_grads)
        .unwrap();
    renderer
        .backward_projection(ctx, &mut encoder, &gaussians, &base, &mut grads)
        .unwrap();
    ctx.submit(encoder.finish());
    assert!(!renderer.sync_capacity(ctx).unwrap().overflowed);
    let images = batch.read_images(ctx).unwrap();
    assert_occupancy_marks_coloured_squares(ctx, &batch, &images);
    (images, grads.download(ctx, case.model.len()).unwrap())
}

/// The batch's occupancy: 1 exactly on the squares where some pixel of the slot's image has a
/// non-zero colour (the object loss skips by it, so a square missed would be a wrong loss).
fn assert_occupancy_marks_coloured_squares(
    ctx: &GpuContext,
    batch: &ObjectBatchOutput<'_>,
    images: &[Vec<[f32; 4]>],
) {
    let (width, height) = (batch.camera.width as usize, batch.camera.height as usize);
    let cell = OCCUPANCY_CELL as usize;
    let cells_x = width.div_ceil(cell);
    let cells = cells_x * height.div_ceil(cell);
    let marked: Vec<u32> = ctx.read_vec(batch.occupancy()).unwrap();
    let mut occupied_squares = 0;
    for (slot, image) in images.iter().enumerate() {
        let mut expected = vec![0u32; cells];
        for (pixel, rgba) in image.iter().enumerate() {
            if rgba[..3].iter().any(|c| *c != 0.0) {
                expected[pixel / width / cell * cells_x + pixel % width / cell] = 1;
            }
        }
        occupied_squares += expected.iter().filter(|m| **m != 0).count();
        assert_eq!(
            marked[slot * cells..(slot + 1) * cells],
            expected[..],
            "slot {slot}'s occupancy"
        );
    }
    assert!(
        occupied_squares > 0 && occupied_squares < cells * images.len(),
        "some squares occupied, not all: {occupied_squares}"
    );
}

/// Largest difference of each Gaussian's parameter gradients, relative to the largest magnitude
/// in that Gaussian's gradient (floor 1e-3), and of the |d mean2d| statistic, relative to itself.
/// Float atomics add in a different order in the two paths, so bits may differ.
fn assert_gradients_match(batched: &Grads, separate: &Grads, tolerance: f64) {
    let batched_parameters = ReferenceGaussians::from_model(&batched.0);
    let separate_parameters = ReferenceGaussians::from_model(&separate.0);
    let mut nonzero = 0;
    for index in 0..separate.0.len() {
        let b = batched_parameters.parameters(index);
        let s = separate_parameters.parameters(index);
        let scale = s.iter().fold(1e-3f64, |m, v| m.max(v.abs()));
        nonzero += usize::from(s.iter().any(|v| *v != 0.0));
        for slot in 0..s.len() {
            let error = (b[slot] - s[slot]).abs() / scale;
            assert!(
                error <= tolerance,
                "gaussian {index} {}: batched {} separate {} (scale {scale})",
                parameter_name(slot),
                b[slot],
                s[slot]
            );
        }
        for axis in 0..2 {
            let (b, s) = (
                batched.1[index][axis] as f64,
                separate.1[index][axis] as f64,
            );
            let error = (b - s).abs() / s.abs().max(1e-3);
            assert!(
                error <= tolerance,
                "gaussian {index} mean2d_abs[{axis}]: batched {b} separate {s}"
            );
        }
    }
    assert!(
        nonzero > separate.0.len() / 10,
        "most Gaussians get gradients"
    );
}

fn assert_batched_matches_separate(ctx: &GpuContext, case: &Case) {
    for variant in RasterVariant::supported(ctx) {
        let (separate_images, separate_grads) = separate(ctx, variant, case);
        let (batched_images, batched_grads) = batched(ctx, variant, case);
        assert_eq!(batched_images.len(), case.slots.len());
        for (slot, (b, s)) in batched_images.iter().zip(&separate_images).enumerate() {
            let error = b
                .iter()
                .zip(s)
                .flat_map(|(b, s)| (0..4).map(move |k| (b[k] - s[k]).abs()))
                .fold(0.0f32, f32::max);
            assert!(
                error <= 1e-6,
                "{variant:?} slot {slot} ({:?}): image differs by {error}",
                case.slots[slot]
            );
        }
        // The id no Gaussian has renders nothing.
        assert!(batched_images[5].iter().all(|p| *p == [0.0; 4]));
        // Every other slot draws something, and only its own object.
        for (slot, image) in batched_images.iter().enumerate().take(5) {
            assert!(image.iter().any(|p| p[3] > 0.1), "slot {slot} is drawn");
        }
        assert_gradients_match(&batched_grads, &separate_grads, 1e-4);
        // Densification's |d mean2d| statistic is the full render's loss alone, as in the
        // released code (object renders have screen-space points of their own).
        let full_only = Case {
            model: case.model.clone(),
            camera: case.camera,
            slots: Vec::new(),
            weights: case.weights[..1].to_vec(),
        };
        let (_, full_grads) = separate(ctx, variant, &full_only);
        for (index, (b, f)) in batched_grads.1.iter().zip(&full_grads.1).enumerate() {
            for axis in 0..2 {
                let error = (b[axis] - f[axis]).abs() / f[axis].abs().max(1e-3);
                assert!(
                    error <= 1e-4,
                    "gaussian {index} mean2d_abs[{axis}]: batched {} full render {}",
                    b[axis],
                    f[axis]
                );
            }
        }
    }
}

#[test]
fn batched_object_renders_match_separate_renders() {
    let Some(ctx) = context() else { return };
    assert_batched_matches_separate(&ctx, &Case::new(7, 300, 64, 48));
}

#[test]
fn batched_object_renders_match_separate_renders_on_dense_tiles() {
    let Some(ctx) = context() else { return };
    // Several hundred splats per tile and a grid that does not divide the image.
    assert_batched_matches_separate(&ctx, &Case::new(11, 3000, 72, 40));
}

#[test]
fn object_batch_rejects_a_filtered_base_and_no_slots() {
    let Some(ctx) = context() else { return };
    let case = Case::new(3, 50, 32, 32);
    let mut renderer = Renderer::new(&ctx).unwrap();
    let gaussians = GpuGaussians::upload(&ctx, &case.model, case.model.len()).unwrap();
    let mut encoder = segsplat_gpu::Encoder::new(&ctx, "test");
    let filtered = RenderSettings {
        filter: ObjectFilter::Object {
            level: Level::Small,
            id: 0,
        },
        ..RenderSettings::default()
    };
    let base = renderer
        .forward(&ctx, &mut encoder, &gaussians, &case.camera, &filtered)
        .unwrap();
    assert!(
        renderer
            .forward_objects(&ctx, &mut encoder, &gaussians, &base, &case.slots)
            .is_err()
    );
    let base = renderer
        .forward(
            &ctx,
            &mut encoder,
            &gaussians,
            &case.camera,
            &full_settings(),
        )
        .unwrap();
    assert!(
        renderer
            .forward_objects(&ctx, &mut encoder, &gaussians, &base, &[])
            .is_err()
    );
}

/// Per-level id maps for `camera`: vertical bands of ids 0..4 whose edges move with the level, so
/// every slot's IoU lands somewhere between 0 and 1 and the three maps differ.
fn band_masks(camera: &RenderCamera) -> [Vec<u32>; 3] {
    let (width, height) = (camera.width as usize, camera.height as usize);
    std::array::from_fn(|level| {
        (0..width * height)
            .map(|pixel| (((pixel % width) * (level + 2) + pixel / width) / 16 % 5) as u32)
            .collect()
    })
}

#[test]
fn mask_iou_counts_match_the_overlap_of_the_read_back_renders() {
    use segsplat_engine::train::mask_iou::MaskIouCounts;
    use segsplat_engine::train::object_loss::rendered_mask_iou;
    let Some(ctx) = context() else { return };
    let case = Case::new(5, 400, 72, 40);
    let masks = band_masks(&case.camera);
    let ids: Vec<wgpu::Buffer> = masks
        .iter()
        .map(|ids| {
            ctx.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("ids"),
                    contents: bytemuck::cast_slice(ids),
                    usage: wgpu::BufferUsages::STORAGE,
                })
        })
        .collect();
    let ids = [&ids[0], &ids[1], &ids[2]];
    let mut renderer = Renderer::new(&ctx).unwrap();
    let gaussians = GpuGaussians::upload(&ctx, &case.model, case.model.len()).unwrap();
    // Pairs 0 and 1 are another view's: they must keep their counts; the batch's are cleared of
    // stale values first.
    let first_pair = 2;
    let counts = MaskIouCounts::new(&ctx, first_pair + case.slots.len()).unwrap();
    let mut encoder = segsplat_gpu::Encoder::new(&ctx, "test");
    let base = renderer
        .forward(
            &ctx,
            &mut encoder,
            &gaussians,
            &case.camera,
            &full_settings(),
        )
        .unwrap();
    let batch = renderer
        .forward_objects(&ctx, &mut encoder, &gaussians, &base, &case.slots)
        .unwrap();
    counts.encode_batch(&ctx, &mut encoder, &batch, ids, first_pair);
    counts.encode_clear(&mut encoder, first_pair, case.slots.len());
    counts.encode_batch(&ctx, &mut encoder, &batch, ids, first_pair);
    ctx.submit(encoder.finish());
    assert!(!renderer.sync_capacity(&ctx).unwrap().overflowed);
    let images = batch.read_images(&ctx).unwrap();
    let ious = counts.read_ious(&ctx).unwrap();
    assert_eq!(ious.len(), first_pair + case.slots.len());
    assert_eq!(&ious[..first_pair], &[0.0, 0.0]);
    let mut between = 0;
    for ((slot, image), iou) in case.slots.iter().zip(&images).zip(&ious[first_pair..]) {
        let alpha = image.iter().map(|pixel| pixel[3]);
        let expected = rendered_mask_iou(alpha, &masks[slot.level.index()], slot.id);
        assert!(
            (iou - expected).abs() < 1e-6,
            "{slot:?}: GPU IoU {iou}, CPU {expected}"
        );
        between += usize::from(*iou > 0.0 && *iou < 1.0);
    }
    assert!(between >= 3, "IoUs {ious:?} should not all be 0 or 1");
}
