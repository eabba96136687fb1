//! The adapter's own fp32 rate with the deformation field's GEMM kernel: the three products of
//! a `width x width` layer over `rows` Gaussians (forward, input gradient, weight gradient split
//! over the rows as the field splits them), timed alone, so `bench --deformation` can say how
//! close the field's passes come to what the kernel reaches on one large, well-shaped layer
//! (docs/benchmarks.md, "The deformation field's arithmetic rate").

use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use wgpu::util::DeviceExt;

use segsplat_gpu::GpuContext;

use super::field_gpu::DeformError;
use super::kernels::{DeformKernels, GemmBuffers, GemmKernel, GemmParams, GemmProduct, RowSplit};

/// One product's rate.
#[derive(Debug, Clone, Serialize)]
pub struct ProductRate {
    /// `forward` (`X W^T`), `input_gradient` (`dZ W`) or `weight_gradient` (`dZ^T X`).
    pub product: &'static str,
    pub rows: u32,
    pub cols: u32,
    pub depth: u32,
    /// Depth splits of the weight gradient (1 for the others).
    pub splits: u32,
    pub ms: f64,
    pub gflops: f64,
    /// Largest difference from an f64 product over sampled outputs (the kernel measured is
    /// the kernel that computes).
    pub max_error: f64,
}

/// The three products' rates and the rate over all of them.
#[derive(Debug, Clone, Serialize)]
pub struct MatmulReport {
    pub kernel: String,
    pub rows: u32,
    pub width: u32,
    pub repeats: u32,
    pub products: Vec<ProductRate>,
    /// Total floating-point operations over total time.
    pub gflops: f64,
}

struct Operands {
    /// `[rows, width]` activations (also the upstream gradient of the input gradient).
    x: wgpu::Buffer,
    x_host: Vec<f32>,
    /// `[width, width]` weights (PyTorch layout `[outputs, inputs]`).
    w: wgpu::Buffer,
    w_host: Vec<f32>,
    out: wgpu::Buffer,
}

fn random_buffer(ctx: &GpuContext, rng: &mut ChaCha8Rng, len: usize) -> (wgpu::Buffer, Vec<f32>) {
    let host: Vec<f32> = (0..len).map(|_| rng.random_range(-1.0f32..1.0)).collect();
    let buffer = ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("matmul bench operand"),
            contents: bytemuck::cast_slice(&host),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        });
    (buffer, host)
}

/// How a product reads its operands: `a[r, d]` and `b[d, c]` as (offset-free) strides.
struct Product {
    product: GemmProduct,
    params: GemmParams,
    splits: u32,
    /// `true` when A is `x` and B is `w` (forward, input gradient); `false` for the weight
    /// gradient, where both are `x`.
    reads_weights: bool,
}

/// `[rows, width] x B` with B read at the given strides: the forward (`W^T`, depth along a
/// weight row) and the input gradient (`W`, depth down a weight column).
fn activation_product(
    product: GemmProduct,
    rows: u32,
    width: u32,
    b_depth_stride: u32,
    b_col_stride: u32,
) -> Product {
    Product {
        product,
        params: GemmParams {
            rows,
            cols: width,
            depth: width,
            depth_per_split: width,
            a_row_stride: width,
            a_depth_stride: 1,
            b_depth_stride,
            b_col_stride,
            c_row_stride: width,
            ..GemmParams::default()
        },
        splits: 1,
        reads_weights: true,
    }
}

fn products(rows: u32, width: u32, split: RowSplit) -> [Product; 3] {
    [
        activation_product(GemmProduct::Forward, rows, width, 1, width),
        activation_product(GemmProduct::InputGradient, rows, width, width, 1),
        Product {
            product: GemmProduct::WeightGradient,
            params: GemmParams {
                rows: width,
                cols: width,
                depth: rows,
                depth_per_split: split.rows_per_split,
                a_row_stride: 1,
                a_depth_stride: width,
                b_depth_stride: width,
                b_col_stride: 1,
                c_row_stride: width,
                c_split_stride: width * width,
                ..GemmParams::default()
            },
            splits: split.splits,
            reads_weights: false,
        },
    ]
}

/// Largest difference between the GPU's first split of `product` and an f64 product, over 64
/// sampled outputs.
fn sampled_error(product: &Product, operands: &Operands, gpu: &[f32]) -> f64 {
    let p = &product.params;
    let b = if product.reads_weights {
        &operands.w_host
    } else {
        &operands.x_host
    };
    let depth = p.depth.min(p.depth_per_split);
    let mut worst: f64 = 0.0;
    for sample in 0..64u32 {
        let row = sample.wrapping_mul(2_654_435_761) % p.rows;
        let col = sample.wrapping_mul(40_503).wrapping_add(17) % p.cols;
        let expected: f64 = (0..depth)
            .map(|d| {
                let a = operands.x_host[(row * p.a_row_stride + d * p.a_depth_stride) as usize];
                let b = b[(d * p.b_depth_stride + col * p.b_col_stride) as usize];
                f64::from(a) * f64::from(b)
            })
            .sum();
        let got = f64::from(gpu[(row * p.c_row_stride + col) as usize]);
        worst = worst.max((got - expected).abs());
    }
    worst
}

/// Times the three products of a `width x width` layer over `rows` Gaussians with `kernel`,
/// each `repeats` times in one submission after an untimed run.
pub fn measure_matmul(
    ctx: &GpuContext,
    kernel: GemmKernel,
    rows: u32,
    width: u32,
    repeats: u32,
) -> Result<MatmulReport, DeformError> {
    let kernels = DeformKernels::with_gemm(ctx, kernel)?;
    let mut rng = ChaCha8Rng::seed_from_u64(0x6e_6d);
    let (x, x_host) = random_buffer(ctx, &mut rng, (rows * width) as usize);
    let (w, w_host) = random_buffer(ctx, &mut rng, (width * width) as usize);
    let split = kernels.row_split(rows);
    let out_words = (rows * width).max(split.splits * width * width) as u64;
    let operands = Operands {
        x,
        x_host,
        w,
        w_host,
        out: ctx.storage_buffer("matmul bench output", out_words * 4)?,
    };
    let repeats = repeats.max(1);
    let mut rates = Vec::new();
    let (mut total_flops, mut total_seconds) = (0.0, 0.0);
    for product in products(rows, width, split) {
        let b = if product.reads_weights {
            &operands.w
        } else {
            &operands.x
        };
        let record = |count: u32| {
            let mut encoder = segsplat_gpu::Encoder::new(ctx, "matmul bench");
            for _ in 0..count {
                kernels.gemm(
                    ctx,
                    &mut encoder,
                    product.product,
                    product.params,
                    product.splits,
                    GemmBuffers {
                        a: &operands.x,
                        b,
                        bias: b,
                        mask: b,
                        c: &operands.out,
                    },
                );
            }
            encoder.finish()
        };
        ctx.submit(record(1));
        ctx.wait_idle()?;
        let gpu: Vec<f32> = ctx.read_vec(&operands.out)?;
        let max_error = sampled_error(&product, &operands, &gpu);
        let commands = record(repeats);
        let started = Instant::now();
        ctx.submit(commands);
        ctx.wait_idle()?;
        let seconds = started.elapsed().as_secs_f64() / f64::from(repeats);
        let p = &product.params;
        let flops = 2.0 * f64::from(p.rows) * f64::from(p.cols) * f64::from(p.depth);
        total_flops += flops;
        total_seconds += seconds;
        rates.push(ProductRate {
            product: product.product.name(),
            rows: p.rows,
            cols: p.cols,
            depth: p.depth,
            splits: product.splits,
            ms: seconds * 1e3,
            gflops: flops / seconds.max(f64::MIN_POSITIVE) / 1e9,
            max_error,
        });
    }
    Ok(MatmulReport {
        kernel: format!("{kernel:?}").to_lowercase(),
        rows,
        width,
        repeats,
        products: rates,
        gflops: total_flops / total_seconds.max(f64::MIN_POSITIVE) / 1e9,
    })
}
