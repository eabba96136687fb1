//! The host's cost of a dispatch with one compute pass per dispatch (how every kernel was
//! recorded before `segsplat_gpu::Encoder`) against consecutive dispatches sharing one pass.
//! Records `DISPATCHES` dispatches of a trivial kernel (one workgroup each, so the device's
//! arithmetic is negligible), alternating eight buffers as a step's kernels do, and times the
//! encoding (bind lookups, recording, `finish`) and the submission with its wait, per dispatch.
//! The two ways take turns, so load on a shared machine falls on both.
//!
//! Run: `cargo bench --bench pass_sharing` (docs/benchmarks.md, "One pass for a step's
//! dispatches"). Under `cargo test --all-targets` it runs a few rounds only; with no adapter it
//! says so and exits.

use std::time::{Duration, Instant};

use segsplat_gpu::{Encoder, GpuContext, Kernel};

/// About what a figurine training step records (109 on the H200 job).
const DISPATCHES: usize = 110;

const SOURCE: &str = "
@group(0) @binding(0) var<storage, read_write> input: array<u32>;
@group(0) @binding(1) var<storage, read_write> output: array<u32>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    output[id.x] = input[id.x] + 1u;
}
";

#[derive(Default)]
struct Totals {
    encode: Duration,
    submit: Duration,
    rounds: u32,
}

impl Totals {
    fn per_dispatch_us(&self, part: Duration) -> f64 {
        part.as_secs_f64() * 1e6 / (f64::from(self.rounds.max(1)) * DISPATCHES as f64)
    }
}

fn round(
    ctx: &GpuContext,
    kernel: &Kernel,
    buffers: &[wgpu::Buffer],
    pass_each: bool,
    totals: &mut Totals,
) -> Result<(), Box<dyn std::error::Error>> {
    let started = Instant::now();
    let mut encoder = Encoder::new(ctx, "pass sharing");
    for index in 0..DISPATCHES {
        let from = &buffers[index % buffers.len()];
        let to = &buffers[(index + 1) % buffers.len()];
        let bound = kernel.bind(ctx, &[from, to]);
        kernel.dispatch(&mut encoder, &bound, [1, 1, 1]);
        if pass_each {
            encoder.end_pass();
        }
    }
    let commands = encoder.finish();
    let encoded = Instant::now();
    ctx.submit(commands);
    ctx.wait_idle()?;
    totals.encode += encoded - started;
    totals.submit += encoded.elapsed();
    totals.rounds += 1;
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let benching = std::env::args().any(|arg| arg == "--bench");
    let ctx = match GpuContext::new_default() {
        Ok(ctx) => ctx,
        Err(error) => {
            println!("pass_sharing: no GPU adapter ({error}), nothing measured");
            return Ok(());
        }
    };
    let kernel = Kernel::new(&ctx, "pass sharing", &[SOURCE], "main", &[])?;
    let buffers = (0..8)
        .map(|index| ctx.storage_buffer(&format!("pass sharing {index}"), 4096))
        .collect::<Result<Vec<_>, _>>()?;
    let rounds = if benching { 300 } else { 3 };
    let mut each = Totals::default();
    let mut shared = Totals::default();
    // Warm-up: the bind-group cache fills and the pipeline is first used.
    round(&ctx, &kernel, &buffers, true, &mut Totals::default())?;
    round(&ctx, &kernel, &buffers, false, &mut Totals::default())?;
    for _ in 0..rounds {
        round(&ctx, &kernel, &buffers, true, &mut each)?;
        round(&ctx, &kernel, &buffers, false, &mut shared)?;
    }
    println!(
        "pass_sharing on {}: {DISPATCHES} dispatches a round, {rounds} rounds each, microseconds a dispatch",
        ctx.report.name
    );
    for (name, totals) in [("a pass per dispatch", &each), ("one shared pass", &shared)] {
        println!(
            "  {name:<20} encode {:6.2}  submit + wait {:6.2}  total {:6.2}",
            totals.per_dispatch_us(totals.encode),
            totals.per_dispatch_us(totals.submit),
            totals.per_dispatch_us(totals.encode + totals.submit),
        );
    }
    Ok(())
}
