//! `segsplat models check DIR`: the model store's load-time checks, offline, one line per file.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use segsplat::config::Config;
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
    }
}

fn check(args: CheckArgs, config_file: Option<PathBuf>) -> anyhow::Result<bool> {
    let config = Config::load(
        config_file.as_deref(),
        std::env::vars(),
        &Default::default(),
    )
    .context("invalid configuration")?;
    let mut options = runtime_options(&config.models);
    if args.ort_library.is_some() {
        options.library = args.ort_library;
    }
    let runtime = OrtRuntime::load(options)?;
    println!(
        "ONNX Runtime {} from {}",
        runtime.version(),
        runtime.library().display()
    );
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
