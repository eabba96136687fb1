//! The object loss against the CPU reference: empty cells skipped, random small objects, and the
//! batched form slot by slot.

use rand::Rng;
use segsplat_engine::OCCUPANCY_CELL;
use segsplat_engine::loss::{
    LossOutputs, MAX_BATCH_SLOTS, MIXED_CELL, ObjectContentHints, ObjectLossImages, ObjectLossSlot,
    RenderLoss, object_cell_map,
};
use segsplat_gpu::GpuContext;

use crate::gpu_support::{gpu_context, new_encoder, seeded_rng, storage_buffer, submit};
use crate::reference::{Rgb, cpu_loss, test_images, to_vec4};
use crate::render_loss::{GpuLoss, assert_matches_cpu, gpu_loss};

/// An object loss's inputs and its CPU reference: the render is `image` where `in_render` holds
/// and black elsewhere, the mask holds object 7 where `in_mask` holds.
struct ObjectCase {
    rendered: Vec<Rgb>,
    ids: Vec<u32>,
    cpu: f64,
    cpu_grad: Vec<Rgb>,
}

const OBJECT: u32 = 7;

impl ObjectCase {
    fn new(
        image: &[Rgb],
        target: &[Rgb],
        (width, height): (usize, usize),
        in_render: impl Fn(usize) -> bool,
        in_mask: impl Fn(usize) -> bool,
    ) -> Self {
        let rendered: Vec<Rgb> = image
            .iter()
            .enumerate()
            .map(|(p, v)| if in_render(p) { *v } else { [0.0; 3] })
            .collect();
        let ids: Vec<u32> = (0..width * height)
            .map(|p| if in_mask(p) { OBJECT } else { 1 })
            .collect();
        let masked_target: Vec<Rgb> = target
            .iter()
            .zip(&ids)
            .map(|(t, &id)| if id == OBJECT { *t } else { [0.0; 3] })
            .collect();
        let (cpu, cpu_grad) = cpu_loss(&rendered, &masked_target, width, height);
        Self {
            rendered,
            ids,
            cpu,
            cpu_grad,
        }
    }

    /// The GPU's object loss into `slot`, after a full loss of `image` has left every
    /// intermediate buffer holding another image's values, as the object losses of a step find
    /// them: a pass that read a cell its predecessor skipped would read those.
    #[allow(clippy::too_many_arguments)]
    fn gpu(
        &self,
        ctx: &GpuContext,
        loss: &mut RenderLoss,
        image: &[Rgb],
        target: &[Rgb],
        (width, height): (usize, usize),
        weight: f32,
        slot: u32,
    ) -> GpuLoss {
        gpu_loss(ctx, loss, image, target, None, width, height, 1.0, 0);
        gpu_loss(
            ctx,
            loss,
            &self.rendered,
            target,
            Some((&self.ids, OBJECT)),
            width,
            height,
            weight,
            slot,
        )
    }
}

/// Whether pixel `p` of a `width`-wide image lies within `r` of (cx, cy).
fn in_disc(width: usize, (cx, cy): (f64, f64), r: f64) -> impl Fn(usize) -> bool {
    move |p| {
        let (x, y) = ((p % width) as f64 - cx, (p / width) as f64 - cy);
        x * x + y * y < r * r
    }
}

#[test]
fn gpu_object_loss_skipping_empty_cells_matches_cpu_reference() {
    let Some(ctx) = gpu_context() else { return };
    let mut loss = RenderLoss::new(ctx).unwrap();
    let mut rng = seeded_rng(9);
    // 22 x 16 skip cells (the last column and row partial): the rendered object sits top left,
    // its mask bottom right, so most cells are beyond every pass's reach of content and are
    // skipped, some only by the first passes.
    let size = (170, 121);
    let (image, target) = test_images(&mut rng, size.0, size.1);
    let case = ObjectCase::new(
        &image,
        &target,
        size,
        in_disc(size.0, (20.0, 18.0), 9.0),
        in_disc(size.0, (140.0, 95.0), 12.0),
    );
    let gpu = case.gpu(ctx, &mut loss, &image, &target, size, 0.5, 3);
    assert_matches_cpu(
        &gpu,
        3,
        0.5,
        case.cpu,
        &case.cpu_grad,
        "sparse masked 170x121",
    );
    // Far from both objects the gradient is written, and exactly zero.
    let far = 60 * size.0 + 90;
    assert_eq!(gpu.grad[far], [0.0; 4]);
}

#[test]
fn gpu_object_loss_skipping_matches_cpu_reference_on_random_small_objects() {
    let Some(ctx) = gpu_context() else { return };
    let mut loss = RenderLoss::new(ctx).unwrap();
    // Small objects at random places, some at the image's edges, in images whose sides are not
    // multiples of the skip cells: every cell boundary a run's reach can cross.
    for seed in 0..6 {
        let mut rng = seeded_rng(100 + seed);
        let size: (usize, usize) = (rng.random_range(40..150), rng.random_range(30..110));
        let (image, target) = test_images(&mut rng, size.0, size.1);
        let disc = |rng: &mut rand_chacha::ChaCha8Rng| {
            let centre = (
                rng.random_range(0.0..size.0 as f64),
                rng.random_range(0.0..size.1 as f64),
            );
            in_disc(size.0, centre, rng.random_range(1.0..7.0))
        };
        let (in_render, in_mask) = (disc(&mut rng), disc(&mut rng));
        let case = ObjectCase::new(&image, &target, size, in_render, in_mask);
        let gpu = case.gpu(ctx, &mut loss, &image, &target, size, 1.0, 1);
        let label = format!("seed {seed}, {}x{}", size.0, size.1);
        assert_matches_cpu(&gpu, 1, 1.0, case.cpu, &case.cpu_grad, &label);
        // The passes' reaches are the least that keep the gradient exact: it is non-zero (on
        // the CPU, in f64) exactly where the GPU computed it, out to the last pixel of its
        // support, whose tiny values the tolerance above could not tell from zero.
        let mut support = 0;
        for (pixel, (gpu_pixel, cpu_pixel)) in gpu.grad.iter().zip(&case.cpu_grad).enumerate() {
            let cpu_nonzero = cpu_pixel.iter().any(|g| *g != 0.0);
            let gpu_nonzero = gpu_pixel[..3].iter().any(|g| *g != 0.0);
            support += usize::from(cpu_nonzero);
            assert_eq!(
                gpu_nonzero,
                cpu_nonzero,
                "{label}: pixel ({}, {}) GPU {gpu_pixel:?} CPU {cpu_pixel:?}",
                pixel % size.0,
                pixel / size.0
            );
        }
        assert!(
            support > 0 && support < size.0 * size.1,
            "{label}: support {support}"
        );
    }
}

/// A step's object losses run as one batch: each slot its own render, mask (one of three id
/// maps) and scratch images. More slots than one set of dispatches holds, so the batch is split;
/// some slots' objects are absent from their map or their render is empty. Each slot's loss and
/// gradient must match its own CPU reference, non-zero exactly where the reference is, and
/// nothing outside the batch's loss values and gradient images may be written.
#[test]
fn gpu_object_loss_batch_matches_cpu_reference_per_slot() {
    let Some(ctx) = gpu_context() else { return };
    let mut loss = RenderLoss::new(ctx).unwrap();
    let mut rng = seeded_rng(11);
    let (width, height) = (37, 29);
    let pixels = width * height;
    let (image, target) = test_images(&mut rng, width, height);
    // Three id maps, each a few overlapping discs with ids 1..=4 on background 0.
    let id_maps: Vec<Vec<u32>> = (0..3)
        .map(|_| {
            let mut ids = vec![0u32; pixels];
            for id in 1..=4u32 {
                let centre = (
                    rng.random_range(0.0..width as f64),
                    rng.random_range(0.0..height as f64),
                );
                let inside = in_disc(width, centre, rng.random_range(2.0..8.0));
                for (pixel, value) in ids.iter_mut().enumerate() {
                    if inside(pixel) {
                        *value = id;
                    }
                }
            }
            ids
        })
        .collect();
    let slot_count = MAX_BATCH_SLOTS as usize + 6;
    let slots: Vec<ObjectLossSlot> = (0..slot_count)
        .map(|slot| ObjectLossSlot {
            id_map: (slot % 3) as u32,
            // Ids 1..=4 are in the maps (or hidden by later discs); 5 never is.
            object_id: 1 + (slot / 3 % 5) as u32,
        })
        .collect();
    // Each slot's render: the image over a random disc, or nothing at all.
    let renders: Vec<Vec<Rgb>> = (0..slot_count)
        .map(|slot| {
            let centre = (
                rng.random_range(0.0..width as f64),
                rng.random_range(0.0..height as f64),
            );
            let inside = in_disc(width, centre, rng.random_range(1.0..9.0));
            (0..pixels)
                .map(|p| {
                    if slot % 7 != 3 && inside(p) {
                        image[p]
                    } else {
                        [0.0; 3]
                    }
                })
                .collect()
        })
        .collect();
    // Image 0 of the rendered and gradient buffers and loss slots 0..2 are not the batch's.
    let (first_image, first_loss) = (1u32, 2u32);
    let mut rendered = to_vec4(&image, 0.5);
    for render in &renders {
        rendered.extend(to_vec4(render, 0.5));
    }
    let rendered_buffer = storage_buffer(ctx, "rendered", &rendered);
    let target_buffer = storage_buffer(ctx, "target", &to_vec4(&target, 1.0));
    let map_buffers: Vec<wgpu::Buffer> = id_maps
        .iter()
        .map(|ids| storage_buffer(ctx, "ids", ids))
        .collect();
    let map_refs: Vec<&wgpu::Buffer> = map_buffers.iter().collect();
    // The renders' occupancy as a batch of object renders marks it (the full image's, image 0,
    // not the batch's, all set), and each map's cell map: the content pass reads these instead of
    // every pixel when given them, with the same losses and gradients.
    let cells_x = width.div_ceil(OCCUPANCY_CELL as usize);
    let cells = cells_x * height.div_ceil(OCCUPANCY_CELL as usize);
    let mut occupancy = vec![1u32; cells];
    for render in &renders {
        let mut marks = vec![0u32; cells];
        for (pixel, rgb) in render.iter().enumerate() {
            if rgb.iter().any(|c| *c != 0.0) {
                let (x, y) = (pixel % width, pixel / width);
                marks[y / OCCUPANCY_CELL as usize * cells_x + x / OCCUPANCY_CELL as usize] = 1;
            }
        }
        occupancy.extend(marks);
    }
    let occupancy_buffer = storage_buffer(ctx, "occupancy", &occupancy);
    let cell_maps: Vec<wgpu::Buffer> = id_maps
        .iter()
        .map(|ids| storage_buffer(ctx, "cell map", &object_cell_map(ids, width as u32)))
        .collect();
    let cell_map_refs: Vec<&wgpu::Buffer> = cell_maps.iter().collect();
    assert!(
        id_maps
            .iter()
            .any(|ids| object_cell_map(ids, width as u32).contains(&MIXED_CELL)),
        "some square holds two objects"
    );
    for hints in [false, true] {
        let grad_buffer =
            storage_buffer(ctx, "grad", &vec![[9.0f32; 4]; pixels * (slot_count + 1)]);
        let loss_buffer = storage_buffer(ctx, "loss values", &vec![-1.0f32; slot_count + 4]);
        // A full loss first leaves every scratch buffer holding another image's values.
        gpu_loss(ctx, &mut loss, &image, &target, None, width, height, 1.0, 0);
        let weight = 0.75;
        let mut encoder = new_encoder(ctx);
        loss.encode_objects(
            ctx,
            &mut encoder,
            &ObjectLossImages {
                rendered: &rendered_buffer,
                rendered_index: first_image,
                target: &target_buffer,
                id_maps: &map_refs,
                slots: &slots,
                width: width as u32,
                height: height as u32,
                content: hints.then_some(ObjectContentHints {
                    occupancy: &occupancy_buffer,
                    cell_maps: &cell_map_refs,
                }),
            },
            weight,
            &LossOutputs {
                rendered_grad: &grad_buffer,
                grad_index: first_image,
                loss_values: &loss_buffer,
                loss_slot: first_loss,
            },
        )
        .unwrap();
        submit(ctx, encoder);
        let loss_values: Vec<f32> = ctx.read_vec(&loss_buffer).unwrap();
        let grads: Vec<[f32; 4]> = ctx.read_vec(&grad_buffer).unwrap();
        assert!(
            grads[..pixels].iter().all(|g| *g == [9.0; 4]),
            "image 0 written"
        );
        for index in
            (0..first_loss as usize).chain(first_loss as usize + slot_count..loss_values.len())
        {
            assert_eq!(loss_values[index], -1.0, "loss value {index} written");
        }
        let mut empty_slots = 0;
        for (slot, object) in slots.iter().enumerate() {
            let ids = &id_maps[object.id_map as usize];
            let masked_target: Vec<Rgb> = target
                .iter()
                .zip(ids)
                .map(|(t, &id)| if id == object.object_id { *t } else { [0.0; 3] })
                .collect();
            let (cpu, cpu_grad) = cpu_loss(&renders[slot], &masked_target, width, height);
            let start = (1 + slot) * pixels;
            let gpu = GpuLoss {
                loss_values: vec![loss_values[first_loss as usize + slot]],
                grad: grads[start..start + pixels].to_vec(),
            };
            let label = format!("slot {slot} ({object:?}), content hints {hints}");
            assert_matches_cpu(&gpu, 0, f64::from(weight), cpu, &cpu_grad, &label);
            for (pixel, (gpu_pixel, cpu_pixel)) in gpu.grad.iter().zip(&cpu_grad).enumerate() {
                assert_eq!(
                    gpu_pixel[..3].iter().any(|g| *g != 0.0),
                    cpu_pixel.iter().any(|g| *g != 0.0),
                    "{label}: pixel {pixel} GPU {gpu_pixel:?} CPU {cpu_pixel:?}"
                );
            }
            empty_slots += usize::from(cpu == 0.0);
        }
        assert!(
            empty_slots > 0 && empty_slots < slot_count,
            "some slots, not all, have neither render nor mask: {empty_slots}"
        );
    }
}
