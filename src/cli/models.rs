//! `segsplat models check DIR`: the model store's load-time checks, offline, one line per file;
//! `segsplat models verify DIR`: real-architecture exports against PyTorch reference outputs.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use segsplat::config::Config;
use segsplat::models::reference_check::check_against_reference;
use segsplat::models::service::runtime_options;
use segsplat::models::{ModelStore, OrtRuntime};

#[derive(Args)]
pub struct ModelsArgs {
    #[command(subcommand)]
    pub command: ModelsCommand,
}

#[derive(Subcommand)]
pub enum ModelsCommand {
    /// Check a model directory: manifest, sha256 of every file, signatures (exit 1 on any problem).
    Check(CheckArgs),
    /// Run real-architecture exports against PyTorch reference outputs
    /// (`scripts/export_models.py --reference-dir`); prints comparisons and timings.
    Verify(VerifyArgs),
}

#[derive(Args)]
pub struct VerifyArgs {
    /// Model directory with manifest.json.
    pub dir: PathBuf,
    /// Reference directory (default: DIR/reference).
    #[arg(long)]
    pub reference: Option<PathBuf>,
    #[arg(long)]
    pub ort_library: Option<PathBuf>,
}

#[derive(Args)]
pub struct CheckArgs {
    /// Model directory with manifest.json.
    pub dir: PathBuf,
    /// ONNX Runtime library (else models.ort_library, ORT_DYLIB_PATH, the onnxruntime wheel).
    #[arg(long)]
    pub ort_library: Option<PathBuf>,
}

/// Returns whether everything checked out; problems are printed, not returned as errors.
pub fn run(args: ModelsArgs, config_file: Option<PathBuf>) -> anyhow::Result<bool> {
    match args.command {
        ModelsCommand::Check(args) => check(args, config_file),
        ModelsCommand::Verify(args) => verify(args, config_file),
    }
}

fn load_runtime(
    config_file: Option<PathBuf>,
    ort_library: Option<PathBuf>,
) -> anyhow::Result<std::sync::Arc<OrtRuntime>> {
    let config = Config::load(
        config_file.as_deref(),
        std::env::vars(),
        &Default::default(),
    )
    .context("invalid configuration")?;
    let mut options = runtime_options(&config.models);
    if ort_library.is_some() {
        options.library = ort_library;
    }
    let runtime = OrtRuntime::load(options)?;
    println!(
        "ONNX Runtime {} from {}",
        runtime.version(),
        runtime.library().display()
    );
    Ok(runtime)
}

fn verify(args: VerifyArgs, config_file: Option<PathBuf>) -> anyhow::Result<bool> {
    let runtime = load_runtime(config_file, args.ort_library)?;
    let started = std::time::Instant::now();
    let store = ModelStore::open(&args.dir, runtime)?;
    println!(
        "opened (hashes and signatures checked) in {:.2} s: {}",
        started.elapsed().as_secs_f64(),
        store.summary()
    );
    let reference = args.reference.unwrap_or_else(|| args.dir.join("reference"));
    let report = check_against_reference(&store, &reference)?;
    for note in &report.notes {
        println!("note  {note}");
    }
    for comparison in &report.comparisons {
        println!(
            "{}  {}: max abs error {:.2e} (tolerance {:.0e})",
            if comparison.passed() {
                "ok     "
            } else {
                "PROBLEM"
            },
            comparison.what,
            comparison.max_abs_error,
            comparison.tolerance
        );
    }
    for (what, seconds) in &report.timings {
        println!("time  {what}: {:.3} s", seconds);
    }
    Ok(report.passed())
}

fn check(args: CheckArgs, config_file: Option<PathBuf>) -> anyhow::Result<bool> {
    let runtime = load_runtime(config_file, args.ort_library)?;
    let report = ModelStore::check(&args.dir, &runtime);
    if let Some(error) = &report.manifest_error {
        println!("manifest  PROBLEM  {error}");
        return Ok(false);
    }
    for file in &report.files {
        let outcome = match &file.result {
            Ok(()) => "OK".to_string(),
            Err(error) => format!("PROBLEM  {error}"),
        };
        println!(
            "{:<12} {:<28} {:<36} {outcome}",
            file.role, file.name, file.file
        );
    }
    Ok(report.is_ok())
}
