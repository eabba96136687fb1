//! `segsplat bench-matmul`: the adapter's own fp32 rate with the deformation field's GEMM kernel
//! (the three products of one layer over many Gaussians), as one JSON object. `bench
//! --deformation` measures the same in its run and sets the field's rate beside it.

use clap::Args;
use segsplat_engine::deform::{GemmKernel, measure_matmul};

#[derive(Args)]
pub struct MatmulArgs {
    /// Rows of the products (Gaussians).
    #[arg(long, default_value_t = 16_384)]
    pub rows: u32,
    /// Width of the layer (the field's default is 256).
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    /// Timed runs of each product (after one untimed run).
    #[arg(long, default_value_t = 5)]
    pub repeats: u32,
    /// Print one JSON object (otherwise a readable summary).
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: MatmulArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.rows > 0 && args.width > 0,
        "--rows and --width must be at least 1"
    );
    let ctx = super::super::open_gpu()?;
    let kernel = GemmKernel::for_adapter(&ctx);
    let report = measure_matmul(&ctx, kernel, args.rows, args.width, args.repeats)?;
    let json = serde_json::json!({
        "adapter": ctx.report.name,
        "backend": ctx.report.backend,
        "matmul": report,
    });
    if args.json {
        println!("{json}");
    } else {
        println!("{}", serde_json::to_string_pretty(&json)?);
    }
    Ok(())
}
