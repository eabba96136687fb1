//! `segsplat train DIR`: plain 3DGS on a local dataset with a progress bar; writes `scene.ply`,
//! `labels.npy`, `metrics.json` and a resumable checkpoint to the output directory.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use std::time::Duration;

use indicatif::{HumanDuration, ProgressBar, ProgressState, ProgressStyle};
use segsplat_engine::checkpoint::Checkpoint;
use segsplat_engine::deform::{DEFORMATION_FILE, DEFORMATION_WEIGHTS_FILE, DeformationConfig};
use segsplat_engine::train::{TrainConfig, Trainer, TrainerMeta};
use segsplat_method::scene_files::{ReconstructMetrics, write_scene_files};

use super::interrupt::{INTERRUPTED_EXIT_CODE, Interrupt};

#[derive(Args)]
pub struct TrainArgs {
    /// Dataset directory (COLMAP, nerfstudio or Blender layout).
    pub dataset: PathBuf,
    /// Output directory (created).
    #[arg(long, default_value = "output")]
    pub out: PathBuf,
    #[arg(long)]
    pub steps: Option<u32>,
    /// Longest image side in pixels.
    #[arg(long)]
    pub max_resolution: Option<u32>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Full training config as JSON (fields as `TrainConfig`); flags override it.
    #[arg(long)]
    pub config_json: Option<PathBuf>,
    /// Continue from `OUT/train.ckpt` when it exists.
    #[arg(long)]
    pub resume: bool,
    /// Steps between checkpoints written to `OUT/train.ckpt` (0 = only at the end).
    #[arg(long, default_value_t = 1000)]
    pub checkpoint_every: u32,
    /// Train a dynamic dataset (frames with times) as a static scene, without the deformation
    /// field it otherwise gets when the config does not set one.
    #[arg(long)]
    pub no_deformation: bool,
}

pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    let mut config: TrainConfig = match &args.config_json {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?
        }
        None => TrainConfig::default(),
    };
    if let Some(steps) = args.steps {
        config.steps = steps;
    }
    if args.max_resolution.is_some() {
        config.max_resolution = args.max_resolution;
    }
    if let Some(seed) = args.seed {
        config.seed = seed;
    }
    // A bad config is named before anything is opened; the field the scene adds is valid.
    config.validate()?;
    let scene = super::open_scene(&args.dataset)?;
    let ctx = super::open_gpu()?;
    if scene.is_dynamic() && config.deformation.is_none() && !args.no_deformation {
        config.deformation = Some(DeformationConfig::default());
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let checkpoint_path = args.out.join("train.ckpt");
    let mut trainer = if args.resume && checkpoint_path.exists() {
        let checkpoint = Checkpoint::<TrainerMeta>::load(&checkpoint_path)?;
        Trainer::resume(&ctx, &scene, &checkpoint)?
    } else {
        Trainer::new(&ctx, &scene, config.clone(), None)?
    };
    for warning in trainer.schedule().warnings() {
        eprintln!("warning: {warning}");
    }
    let total = trainer.config().steps;
    let resumed_from = trainer.step();
    let bar = ProgressBar::new(total as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps  {msg}  [{elapsed} < {eta}]")
            .map(|style| style.with_key("eta", session_eta(resumed_from)))
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_position(resumed_from as u64);
    let interrupt = Interrupt::install()?;
    eprintln!(
        "training steps {resumed_from}..{total}; Ctrl-C stops with a checkpoint in {}",
        checkpoint_path.display()
    );
    let started = std::time::Instant::now();
    while trainer.step() < trainer.end_step() && !interrupt.requested() {
        let next = match args.checkpoint_every {
            0 => total,
            // Saturating: a cadence near u32::MAX must not wrap to an earlier step.
            every => (trainer.step() / every + 1)
                .saturating_mul(every)
                .min(total),
        };
        trainer.run_until(next, |progress| {
            bar.set_position(progress.step as u64);
            bar.set_message(format!(
                "loss {:.4}  {} Gaussians  {:.1} steps/s",
                progress.loss, progress.gaussians, progress.steps_per_sec
            ));
            !interrupt.requested()
        })?;
        trainer.checkpoint()?.save(&checkpoint_path)?;
    }
    if interrupt.requested() {
        bar.abandon();
        eprintln!(
            "stopped at step {} of {total}; checkpoint written to {}\nresume with: segsplat train {} --out {} --resume",
            trainer.step(),
            checkpoint_path.display(),
            args.dataset.display(),
            args.out.display()
        );
        std::process::exit(INTERRUPTED_EXIT_CODE);
    }
    bar.finish();
    let train_seconds = started.elapsed().as_secs_f64();
    let held_out = trainer.evaluate()?;
    let model = trainer.model()?;
    write_scene_files(&model, &scene, &args.out)?;
    if let Some(stored) = trainer.stored_deformation(&scene.frame_times())? {
        std::fs::write(args.out.join(DEFORMATION_FILE), stored.header_bytes()?)?;
        std::fs::write(
            args.out.join(DEFORMATION_WEIGHTS_FILE),
            stored.weight_bytes(),
        )?;
    }
    let metrics = ReconstructMetrics {
        steps: trainer.step(),
        gaussians: model.len(),
        train_seconds,
        held_out,
    };
    std::fs::write(
        args.out.join("metrics.json"),
        serde_json::to_vec_pretty(&metrics)?,
    )?;
    println!(
        "{} Gaussians; held-out PSNR {:.2} dB, SSIM {:.4} over {} views; wrote {}",
        metrics.gaussians,
        metrics.held_out.psnr,
        metrics.held_out.ssim,
        metrics.held_out.views,
        args.out.join("scene.ply").display()
    );
    Ok(())
}

/// The `{eta}` of the bar, from this session's rate alone: after `--resume` the bar starts at
/// the checkpoint's step, and indicatif's own estimate would count those steps as done in the
/// first instant.
fn session_eta(
    resumed_from: u32,
) -> impl Fn(&ProgressState, &mut dyn std::fmt::Write) + Send + Sync + Clone + 'static {
    move |state, out| {
        let remaining = remaining_time(
            state.pos(),
            state.len().unwrap_or(0),
            u64::from(resumed_from),
            state.elapsed(),
        );
        let _ = match remaining {
            Some(eta) => write!(out, "{}", HumanDuration(eta)),
            None => write!(out, "?"),
        };
    }
}

/// Time left at this session's rate: `done_now - resumed_from` steps took `elapsed`.
fn remaining_time(
    position: u64,
    length: u64,
    resumed_from: u64,
    elapsed: Duration,
) -> Option<Duration> {
    let done = position
        .checked_sub(resumed_from)
        .filter(|&done| done > 0)?;
    let left = length.saturating_sub(position);
    Some(elapsed.mul_f64(left as f64 / done as f64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resumed_steps_do_not_count_as_done_this_session() {
        // Resumed at 900 of 1000; 50 steps took 10 s: 50 left take 10 s more.
        let eta = remaining_time(950, 1000, 900, Duration::from_secs(10));
        assert_eq!(eta, Some(Duration::from_secs(10)));
        // Nothing done yet this session: no estimate rather than a wrong one.
        assert_eq!(remaining_time(900, 1000, 900, Duration::from_secs(3)), None);
        assert_eq!(
            remaining_time(100, 1000, 0, Duration::from_secs(1)),
            Some(Duration::from_secs(9))
        );
    }
}
