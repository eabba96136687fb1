//! `segsplat models check DIR`: the model store's load-time checks, offline, one line per file;
//! `segsplat models verify DIR`: real-architecture exports against PyTorch reference outputs.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use segsplat_service::config::Config;
use segsplat_vision::models::init::{InitOptions, init_model_dir};
use segsplat_vision::models::manifest::Family;
use segsplat_vision::models::reference_check::check_against_reference;
use segsplat_vision::models::service::runtime_options;
use segsplat_vision::models::{ModelStore, OrtRuntime};

#[derive(Args)]
pub struct ModelsArgs {
    #[command(subcommand)]
    pub command: ModelsCommand,
}

#[derive(Subcommand)]
pub enum ModelsCommand {
    /// Check a model directory: manifest, sha256 of every file, signatures (exit 1 on any problem).
    Check(CheckArgs),
    /// Write manifest.json for a folder of ONNX files (roles recognised from their graphs), then
    /// check it.
    Init(InitArgs),
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
pub struct InitArgs {
    /// Folder with the .onnx files (and the tokenizer file for a CLIP text model).
    pub dir: PathBuf,
    /// CLIP image normalisation mean, three comma-separated values in 0..1 (default: OpenAI's).
    #[arg(long, value_parser = parse_triple)]
    pub clip_mean: Option<[f32; 3]>,
    /// CLIP image normalisation std (default: OpenAI's).
    #[arg(long, value_parser = parse_triple)]
    pub clip_std: Option<[f32; 3]>,
    /// CLIP image side, for graphs whose input side is dynamic.
    #[arg(long)]
    pub clip_image_size: Option<u32>,
    /// SAM family when the graph cannot tell: sam (SAM 1) or mobile_sam (default: mobile_sam
    /// when a file name says "mobile", else sam). SAM 2 is told from its graph.
    #[arg(long, value_parser = parse_sam_family)]
    pub sam_family: Option<Family>,
    /// Replace an existing manifest.json.
    #[arg(long)]
    pub force: bool,
    /// The CLIP text model's tokenizer file in DIR (default: tokenizer.json, else the one
    /// *tokenizer*.json there).
    #[arg(long)]
    pub tokenizer: Option<PathBuf>,
    #[arg(long)]
    pub ort_library: Option<PathBuf>,
}

fn parse_triple(text: &str) -> Result<[f32; 3], String> {
    let values: Vec<f32> = text
        .split(',')
        .map(|part| part.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|error| format!("{text:?}: {error}"))?;
    <[f32; 3]>::try_from(values)
        .map_err(|values| format!("{text:?}: expected 3 values, got {}", values.len()))
}

fn parse_sam_family(text: &str) -> Result<Family, String> {
    match text {
        "sam" => Ok(Family::Sam),
        "mobile_sam" | "mobilesam" => Ok(Family::MobileSam),
        other => Err(format!(
            "{other:?}: expected sam or mobile_sam (SAM 2 is recognised from its graph)"
        )),
    }
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
        ModelsCommand::Init(args) => init(args, config_file),
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

fn init(args: InitArgs, config_file: Option<PathBuf>) -> anyhow::Result<bool> {
    let runtime = load_runtime(config_file, args.ort_library)?;
    let options = InitOptions {
        clip_mean: args.clip_mean,
        clip_std: args.clip_std,
        clip_image_size: args.clip_image_size,
        sam_family: args.sam_family,
        overwrite: args.force,
        tokenizer: args.tokenizer,
    };
    let report = init_model_dir(&args.dir, &runtime, &options)?;
    for model in &report.models {
        println!(
            "{:<12} {:<36} {:?}",
            model.role.as_str(),
            model.file,
            model.family
        );
        for output in &model.extra_outputs {
            println!("             extra output {output}");
        }
        for assumption in &model.assumed {
            println!("             assumed: {assumption}");
        }
        for finding in &model.findings {
            println!("             found: {finding}");
        }
    }
    if let Some(tokenizer) = &report.tokenizer {
        println!("{:<12} {tokenizer}", "tokenizer");
    }
    for (file, why) in &report.skipped {
        println!("skipped      {file}: {why}");
    }
    println!("wrote {}; checking it:", report.manifest.display());
    Ok(print_check(&args.dir, &runtime))
}

fn check(args: CheckArgs, config_file: Option<PathBuf>) -> anyhow::Result<bool> {
    let runtime = load_runtime(config_file, args.ort_library)?;
    Ok(print_check(&args.dir, &runtime))
}

/// Prints one line per file (and its notes); true when everything checked out.
fn print_check(dir: &std::path::Path, runtime: &OrtRuntime) -> bool {
    let report = ModelStore::check(dir, runtime);
    if let Some(error) = &report.manifest_error {
        println!("manifest  PROBLEM  {error}");
        return false;
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
        for note in &file.notes {
            println!("{:<12} note: {note}", "");
        }
    }
    report.is_ok()
}
