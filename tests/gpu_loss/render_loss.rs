//! The GPU render loss against the CPU reference: values, gradients, odd sizes, a masked target.

use segsplat_engine::loss::{LossImages, LossOutputs, ObjectMask, RenderLoss};
use segsplat_gpu::GpuContext;

use crate::gpu_support::{gpu_context, new_encoder, seeded_rng, storage_buffer, submit};
use crate::reference::{Rgb, central_difference, cpu_loss, test_images, to_vec4};

/// What the GPU computed for one call.
pub(crate) struct GpuLoss {
    pub(crate) loss_values: Vec<f32>,
    pub(crate) grad: Vec<[f32; 4]>,
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn gpu_loss(
    ctx: &GpuContext,
    loss: &mut RenderLoss,
    rendered: &[Rgb],
    target: &[Rgb],
    mask: Option<(&[u32], u32)>,
    width: usize,
    height: usize,
    weight: f32,
    slot: u32,
) -> GpuLoss {
    let rendered_buffer = storage_buffer(ctx, "rendered", &to_vec4(rendered, 0.7));
    let target_buffer = storage_buffer(ctx, "target", &to_vec4(target, 1.0));
    let ids_buffer = mask.map(|(ids, _)| storage_buffer(ctx, "ids", ids));
    let grad_buffer = storage_buffer(ctx, "grad", &vec![[9.0f32; 4]; width * height]);
    let loss_buffer = storage_buffer(ctx, "loss values", &[-1.0f32; 6]);
    let images = LossImages {
        rendered: &rendered_buffer,
        rendered_index: 0,
        target: &target_buffer,
        target_mask: mask.map(|(_, object_id)| ObjectMask {
            object_ids: ids_buffer.as_ref().unwrap(),
            object_id,
        }),
        width: width as u32,
        height: height as u32,
    };
    let outputs = LossOutputs {
        rendered_grad: &grad_buffer,
        grad_index: 0,
        loss_values: &loss_buffer,
        loss_slot: slot,
    };
    let mut encoder = new_encoder(ctx);
    loss.encode(ctx, &mut encoder, &images, weight, &outputs)
        .unwrap();
    submit(ctx, encoder);
    GpuLoss {
        loss_values: ctx.read_vec(&loss_buffer).unwrap(),
        grad: ctx.read_vec(&grad_buffer).unwrap(),
    }
}

pub(crate) fn assert_matches_cpu(
    gpu: &GpuLoss,
    slot: usize,
    weight: f64,
    cpu_loss: f64,
    cpu_grad: &[Rgb],
    label: &str,
) {
    let expected = weight * cpu_loss;
    let got = f64::from(gpu.loss_values[slot]);
    assert!(
        (got - expected).abs() <= 2e-6 * expected.abs() + 1e-6,
        "{label}: loss {got} vs CPU {expected}"
    );
    for (index, value) in gpu.loss_values.iter().enumerate() {
        if index != slot {
            assert_eq!(*value, -1.0, "{label}: loss slot {index} was written");
        }
    }
    let scale = cpu_grad
        .iter()
        .flatten()
        .fold(0.0f64, |m, g| m.max(g.abs()))
        * weight;
    let mut worst = 0.0f64;
    for (gpu_pixel, cpu_pixel) in gpu.grad.iter().zip(cpu_grad) {
        assert_eq!(gpu_pixel[3], 0.0, "{label}: gradient w must be 0");
        for c in 0..3 {
            worst = worst.max((f64::from(gpu_pixel[c]) - weight * cpu_pixel[c]).abs());
        }
    }
    eprintln!(
        "{label}: loss {got} (CPU {expected}), gradient max abs error {worst:e} of {scale:e}"
    );
    assert!(
        worst <= 1e-4 * scale,
        "{label}: gradient max abs error {worst:e} vs largest gradient {scale:e}"
    );
}

#[test]
fn gpu_loss_matches_cpu_reference_on_odd_sizes() {
    let Some(ctx) = gpu_context() else { return };
    let mut loss = RenderLoss::new(ctx).unwrap();
    let mut rng = seeded_rng(2);
    for (width, height, weight, slot) in [
        (20, 17, 1.0, 0),
        (33, 31, 2.5, 3),
        (5, 3, 1.0, 1),
        (64, 48, 0.5, 5),
    ] {
        let (rendered, target) = test_images(&mut rng, width, height);
        let (cpu, cpu_grad) = cpu_loss(&rendered, &target, width, height);
        let gpu = gpu_loss(
            ctx, &mut loss, &rendered, &target, None, width, height, weight, slot,
        );
        let label = format!("{width}x{height} weight {weight}");
        assert_matches_cpu(
            &gpu,
            slot as usize,
            f64::from(weight),
            cpu,
            &cpu_grad,
            &label,
        );
    }
}

#[test]
fn gpu_object_loss_masks_the_target_to_the_object() {
    let Some(ctx) = gpu_context() else { return };
    let mut loss = RenderLoss::new(ctx).unwrap();
    let mut rng = seeded_rng(4);
    let (width, height) = (20, 17);
    let (rendered, target) = test_images(&mut rng, width, height);
    // Object 7 is a disc; other pixels carry other ids.
    let ids: Vec<u32> = (0..width * height)
        .map(|p| {
            let (x, y) = ((p % width) as f64 - 9.0, (p / width) as f64 - 8.0);
            if x * x + y * y < 30.0 {
                7
            } else {
                (p % 3) as u32
            }
        })
        .collect();
    let masked_target: Vec<Rgb> = target
        .iter()
        .zip(&ids)
        .map(|(t, &id)| if id == 7 { *t } else { [0.0; 3] })
        .collect();
    let (cpu, cpu_grad) = cpu_loss(&rendered, &masked_target, width, height);
    let gpu = gpu_loss(
        ctx,
        &mut loss,
        &rendered,
        &target,
        Some((&ids, 7)),
        width,
        height,
        1.0,
        2,
    );
    assert_matches_cpu(&gpu, 2, 1.0, cpu, &cpu_grad, "masked 20x17");
    // The unmasked loss differs, so the mask had an effect.
    let (unmasked, _) = cpu_loss(&rendered, &target, width, height);
    assert!((unmasked - cpu).abs() > 1e-2);
}

#[test]
fn gpu_loss_gradient_matches_finite_differences_of_the_reference() {
    let Some(ctx) = gpu_context() else { return };
    let mut loss = RenderLoss::new(ctx).unwrap();
    let mut rng = seeded_rng(6);
    let (width, height) = (17, 11);
    let (rendered, target) = test_images(&mut rng, width, height);
    let gpu = gpu_loss(
        ctx, &mut loss, &rendered, &target, None, width, height, 1.0, 0,
    );
    let scale = gpu
        .grad
        .iter()
        .flat_map(|p| &p[..3])
        .fold(0.0f32, |m, g| m.max(g.abs()));
    let step = 1e-6;
    for pixel in [0, 7, width * 5 + 8, width * height - 1] {
        for channel in 0..3 {
            let numeric =
                central_difference(&rendered, &target, (width, height), (pixel, channel), step);
            let analytic = f64::from(gpu.grad[pixel][channel]);
            assert!(
                (numeric - analytic).abs() <= 1e-3 * f64::from(scale),
                "pixel {pixel} channel {channel}: finite difference {numeric:e} GPU {analytic:e}"
            );
        }
    }
}

#[test]
fn identical_images_have_zero_loss_and_gradient() {
    let Some(ctx) = gpu_context() else { return };
    let mut loss = RenderLoss::new(ctx).unwrap();
    let mut rng = seeded_rng(8);
    let (_, target) = test_images(&mut rng, 19, 23);
    let gpu = gpu_loss(ctx, &mut loss, &target, &target, None, 19, 23, 1.0, 0);
    assert!(
        gpu.loss_values[0].abs() < 1e-6,
        "loss {}",
        gpu.loss_values[0]
    );
    let worst = gpu
        .grad
        .iter()
        .flat_map(|p| &p[..3])
        .fold(0.0f32, |m, g| m.max(g.abs()));
    assert!(worst < 1e-6, "gradient {worst}");
}
