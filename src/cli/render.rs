//! `segsplat render DIR --ply FILE`: renders a trained scene from the dataset's views to PNGs.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use segsplat_engine::ply::read_ply_file;
use segsplat_engine::render::Renderer;
use segsplat_engine::train::views::is_held_out;
use segsplat_engine::{GpuGaussians, RenderCamera, RenderSettings};

#[derive(Clone, Copy, ValueEnum)]
pub enum Split {
    /// Held-out views only (every 8th, or the dataset's own test split).
    Test,
    Train,
    All,
}

#[derive(Args)]
pub struct RenderArgs {
    /// Dataset directory whose cameras to render from.
    pub dataset: PathBuf,
    /// Trained scene (Inria-layout PLY, e.g. from `segsplat train`).
    #[arg(long)]
    pub ply: PathBuf,
    /// Output directory for `<frame name>.png`.
    #[arg(long, default_value = "renders")]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value = "test")]
    pub split: Split,
    /// Longest image side in pixels.
    #[arg(long)]
    pub max_resolution: Option<u32>,
    /// Every n-th view is held out (as in training).
    #[arg(long, default_value_t = 8)]
    pub eval_split_every: u32,
    /// Background as `r,g,b` in 0..1.
    #[arg(long, value_delimiter = ',', num_args = 3, default_values_t = [0.0, 0.0, 0.0])]
    pub background: Vec<f32>,
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    let scene = super::open_scene(&args.dataset)?;
    let imported =
        read_ply_file(&args.ply).with_context(|| format!("cannot read {}", args.ply.display()))?;
    let ctx = super::open_gpu()?;
    let gaussians = GpuGaussians::upload(&ctx, &imported.model, imported.model.len())?;
    let mut renderer = Renderer::new(&ctx)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let settings = RenderSettings {
        background: [args.background[0], args.background[1], args.background[2]],
        sh_degree: imported.sh_degree,
        ..Default::default()
    };
    let mut written = 0;
    for (index, frame) in scene.frames.iter().enumerate() {
        let held_out = is_held_out(&scene, index, args.eval_split_every);
        let wanted = match args.split {
            Split::Test => held_out,
            Split::Train => !held_out,
            Split::All => true,
        };
        if !wanted {
            continue;
        }
        let longest = frame.intrinsics.width.max(frame.intrinsics.height);
        let scale = args
            .max_resolution
            .map_or(1.0, |max| (max as f32 / longest as f32).min(1.0));
        let camera = RenderCamera::from_frame(frame, scale)?;
        let output = renderer.render_checked(&ctx, &gaussians, &camera, &settings)?;
        let pixels = output.read_image(&ctx)?;
        let rgb: Vec<u8> = pixels
            .iter()
            .take(camera.pixel_count())
            .flat_map(|p| [p[0], p[1], p[2]])
            .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        let image = image::RgbImage::from_raw(camera.width, camera.height, rgb)
            .context("rendered image has the wrong size")?;
        let stem = std::path::Path::new(&frame.name)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| format!("frame_{index:05}"));
        let path = args.out.join(format!("{stem}.png"));
        image
            .save(&path)
            .with_context(|| format!("cannot write {}", path.display()))?;
        written += 1;
    }
    println!("wrote {written} images to {}", args.out.display());
    Ok(())
}
