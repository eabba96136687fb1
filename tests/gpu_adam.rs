//! GPU Adam against an f64 CPU Adam (PyTorch's formulation) over several steps with changing
//! gradients and learning rates. Tolerance: parameters within 1e-6 absolute (they move by about
//! the learning rate per step; f32 rounding is about 1e-8), second moments within 1e-5 relative,
//! first moments within 1e-5 relative plus 1e-6 of the element's largest gradient.

mod gpu_support;

use gpu_support::{gpu_context, new_encoder, seeded_rng, storage_buffer, submit};
use rand::Rng;
use segsplat_engine::adam::{Adam, AdamBuffers, AdamGroup, AdamSettings};
use segsplat_gpu::GpuContext;

#[derive(Clone)]
struct CpuAdamState {
    params: Vec<f64>,
    first_moment: Vec<f64>,
    second_moment: Vec<f64>,
    /// Largest |gradient| each element has seen: the first moment sums gradients of both signs,
    /// so its f32 rounding error is relative to this, not to the moment.
    gradient_scale: Vec<f64>,
}

fn cpu_adam_step(
    state: &mut CpuAdamState,
    grads: &[f32],
    settings: &AdamSettings,
    lr: f64,
    step: u32,
) {
    let correction1 = 1.0 - settings.beta1.powi(step as i32);
    let correction2 = 1.0 - settings.beta2.powi(step as i32);
    for (i, &g) in grads.iter().enumerate() {
        let g = f64::from(g);
        state.gradient_scale[i] = state.gradient_scale[i].max(g.abs());
        if settings.skip_zero_gradients && g == 0.0 {
            continue;
        }
        let m = settings.beta1 * state.first_moment[i] + (1.0 - settings.beta1) * g;
        let v = settings.beta2 * state.second_moment[i] + (1.0 - settings.beta2) * g * g;
        state.first_moment[i] = m;
        state.second_moment[i] = v;
        state.params[i] -=
            lr / correction1 * m / (v.sqrt() / correction2.sqrt() + settings.epsilon);
    }
}

struct GpuAdamState {
    params: wgpu::Buffer,
    grads: wgpu::Buffer,
    first_moment: wgpu::Buffer,
    second_moment: wgpu::Buffer,
}

impl GpuAdamState {
    fn new(ctx: &GpuContext, params: &[f32]) -> Self {
        let zeros = vec![0.0f32; params.len()];
        Self {
            params: storage_buffer(ctx, "params", params),
            grads: storage_buffer(ctx, "grads", &zeros),
            first_moment: storage_buffer(ctx, "m", &zeros),
            second_moment: storage_buffer(ctx, "v", &zeros),
        }
    }

    fn buffers(&self) -> AdamBuffers<'_> {
        AdamBuffers {
            params: &self.params,
            grads: &self.grads,
            first_moment: &self.first_moment,
            second_moment: &self.second_moment,
        }
    }
}

fn assert_state_matches(
    ctx: &GpuContext,
    gpu: &GpuAdamState,
    cpu: &CpuAdamState,
    count: usize,
    label: &str,
) {
    let params: Vec<f32> = ctx.read_vec(&gpu.params).unwrap();
    let m: Vec<f32> = ctx.read_vec(&gpu.first_moment).unwrap();
    let v: Vec<f32> = ctx.read_vec(&gpu.second_moment).unwrap();
    for i in 0..count {
        let close = |gpu: f32, cpu: f64, relative: f64, absolute: f64| {
            (f64::from(gpu) - cpu).abs() <= relative * cpu.abs() + absolute
        };
        assert!(
            close(params[i], cpu.params[i], 0.0, 1e-6)
                && close(
                    m[i],
                    cpu.first_moment[i],
                    1e-5,
                    1e-6 * cpu.gradient_scale[i]
                )
                && close(v[i], cpu.second_moment[i], 1e-5, 1e-30),
            "{label}: element {i}: GPU (p {}, m {}, v {}) CPU (p {}, m {}, v {})",
            params[i],
            m[i],
            v[i],
            cpu.params[i],
            cpu.first_moment[i],
            cpu.second_moment[i]
        );
    }
}

fn run_steps(
    settings: AdamSettings,
    count: usize,
    buffer_len: usize,
    steps: u32,
    zero_fraction: f64,
) {
    let Some(ctx) = gpu_context() else { return };
    let adam = Adam::new(ctx, settings).unwrap();
    let mut rng = seeded_rng(u64::from(steps) + count as u64);
    let initial: Vec<f32> = (0..buffer_len)
        .map(|_| rng.random_range(-2.0..2.0))
        .collect();
    let gpu = GpuAdamState::new(ctx, &initial);
    let mut cpu = CpuAdamState {
        params: initial.iter().map(|&p| f64::from(p)).collect(),
        first_moment: vec![0.0; count],
        second_moment: vec![0.0; count],
        gradient_scale: vec![0.0; count],
    };
    for step in 1..=steps {
        // Gradients over six orders of magnitude, some exactly zero.
        let grads: Vec<f32> = (0..buffer_len)
            .map(|_| {
                if rng.random_bool(zero_fraction) {
                    0.0
                } else {
                    rng.random_range(-1.0f32..1.0) * 10f32.powi(rng.random_range(-5..2))
                }
            })
            .collect();
        let lr = 1e-2 * 0.7f64.powi(step as i32);
        ctx.queue
            .write_buffer(&gpu.grads, 0, bytemuck::cast_slice(&grads));
        let mut encoder = new_encoder(ctx);
        adam.encode_step(
            ctx,
            &mut encoder,
            &gpu.buffers(),
            count as u32,
            lr as f32,
            step,
        )
        .unwrap();
        submit(ctx, encoder);
        cpu_adam_step(
            &mut cpu,
            &grads[..count],
            &settings,
            f64::from(lr as f32),
            step,
        );
    }
    let label = format!("{count} elements, {steps} steps, {settings:?}");
    assert_state_matches(ctx, &gpu, &cpu, count, &label);
    let params: Vec<f32> = ctx.read_vec(&gpu.params).unwrap();
    assert_eq!(
        &params[count..],
        &initial[count..],
        "{label}: elements beyond the count changed"
    );
}

#[test]
fn dense_adam_matches_cpu_over_several_steps() {
    run_steps(AdamSettings::default(), 10_000, 10_123, 6, 0.1);
}

#[test]
fn sparse_adam_leaves_zero_gradient_elements_untouched() {
    let settings = AdamSettings {
        skip_zero_gradients: true,
        ..AdamSettings::default()
    };
    run_steps(settings, 5_000, 5_000, 4, 0.5);
}

#[test]
fn adam_covers_counts_beyond_one_dispatch_dimension() {
    // 65535 groups of 256 cover 16_776_960 elements; more needs the second grid dimension.
    run_steps(AdamSettings::default(), 16_800_000, 16_800_001, 1, 0.0);
}

#[test]
fn adam_steps_recorded_together_keep_their_own_learning_rates() {
    let Some(ctx) = gpu_context() else { return };
    let settings = AdamSettings::default();
    let adam = Adam::new(ctx, settings).unwrap();
    let groups: Vec<GpuAdamState> = (0..3)
        .map(|_| GpuAdamState::new(ctx, &[1.0f32; 64]))
        .collect();
    for group in &groups {
        ctx.queue
            .write_buffer(&group.grads, 0, bytemuck::cast_slice(&[0.5f32; 64]));
    }
    let mut encoder = new_encoder(ctx);
    let rates = [1e-3f32, 1e-2, 1e-1];
    for (group, &lr) in groups.iter().zip(&rates) {
        adam.encode_step(ctx, &mut encoder, &group.buffers(), 64, lr, 1)
            .unwrap();
    }
    submit(ctx, encoder);
    for (group, &lr) in groups.iter().zip(&rates) {
        // Step 1 moves every parameter by lr * sign(g) (up to epsilon).
        let params: Vec<f32> = ctx.read_vec(&group.params).unwrap();
        assert!(
            params.iter().all(|&p| (p - (1.0 - lr)).abs() < 1e-6),
            "lr {lr}: {:?}",
            &params[..4]
        );
    }
}

#[test]
fn adam_rejects_step_zero_and_short_buffers() {
    let Some(ctx) = gpu_context() else { return };
    let adam = Adam::new(ctx, AdamSettings::default()).unwrap();
    let state = GpuAdamState::new(ctx, &[0.0f32; 16]);
    let mut encoder = new_encoder(ctx);
    assert!(
        adam.encode_step(ctx, &mut encoder, &state.buffers(), 16, 1e-3, 0)
            .is_err()
    );
    assert!(
        adam.encode_step(ctx, &mut encoder, &state.buffers(), 17, 1e-3, 1)
            .is_err()
    );
}

/// Three groups of different sizes, some gradients exactly zero, stepped three times by
/// `encode_steps` (one dispatch where the adapter allows) and by `encode_step` per group.
fn steps_together_and_apart(settings: AdamSettings) -> (Vec<Vec<f32>>, Vec<Vec<f32>>) {
    let Some(ctx) = gpu_context() else {
        return (Vec::new(), Vec::new());
    };
    let adam = Adam::new(ctx, settings).unwrap();
    let mut rng = seeded_rng(17);
    let sizes = [100usize, 37, 300];
    let rates = [1e-3f32, 5e-2, 2e-4];
    let initial: Vec<Vec<f32>> = sizes
        .iter()
        .map(|&n| (0..n).map(|_| rng.random_range(-1.0f32..1.0)).collect())
        .collect();
    let together: Vec<GpuAdamState> = initial.iter().map(|p| GpuAdamState::new(ctx, p)).collect();
    let apart: Vec<GpuAdamState> = initial.iter().map(|p| GpuAdamState::new(ctx, p)).collect();
    for step in 1..=3 {
        for (g, &n) in sizes.iter().enumerate() {
            let grads: Vec<f32> = (0..n)
                .map(|i| {
                    if i % 7 == 0 {
                        0.0
                    } else {
                        rng.random_range(-1.0f32..1.0)
                    }
                })
                .collect();
            for state in [&together[g], &apart[g]] {
                ctx.queue
                    .write_buffer(&state.grads, 0, bytemuck::cast_slice(&grads));
            }
        }
        let mut encoder = new_encoder(ctx);
        let groups: Vec<AdamGroup<'_>> = together
            .iter()
            .zip(sizes.iter().zip(&rates))
            .map(|(state, (&n, &lr))| AdamGroup {
                buffers: state.buffers(),
                element_count: n as u32,
                learning_rate: lr,
            })
            .collect();
        adam.encode_steps(ctx, &mut encoder, &groups, step).unwrap();
        for (state, (&n, &lr)) in apart.iter().zip(sizes.iter().zip(&rates)) {
            adam.encode_step(ctx, &mut encoder, &state.buffers(), n as u32, lr, step)
                .unwrap();
        }
        submit(ctx, encoder);
    }
    let read = |states: &[GpuAdamState]| -> Vec<Vec<f32>> {
        states
            .iter()
            .flat_map(|s| [&s.params, &s.first_moment, &s.second_moment])
            .map(|b| ctx.read_vec(b).unwrap())
            .collect()
    };
    (read(&together), read(&apart))
}

#[test]
fn adam_groups_in_one_dispatch_match_one_dispatch_per_group() {
    for skip_zero_gradients in [false, true] {
        let (together, apart) = steps_together_and_apart(AdamSettings {
            skip_zero_gradients,
            ..AdamSettings::default()
        });
        for (a, b) in together.iter().zip(&apart) {
            for (x, y) in a.iter().zip(b) {
                assert!(
                    (x - y).abs() <= 1e-6 * y.abs().max(1e-3),
                    "skip {skip_zero_gradients}: {x} against {y}"
                );
            }
        }
    }
}
