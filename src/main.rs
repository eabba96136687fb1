//! The `segsplat` command line: parse, load the configuration, call into the library.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

mod cli;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use segsplat_api::{ServiceBuilder, ServiceMode};
use segsplat_service::config::{Config, ConfigOverrides, LogFormat};

#[derive(Parser)]
#[command(
    name = "segsplat",
    version,
    about = "Open-vocabulary 3D segmentation with Segment-then-Splat Gaussian scenes"
)]
struct Cli {
    /// TOML configuration file (keys as in README; SEGSPLAT_* variables and flags override it).
    #[arg(long, global = true, env = "SEGSPLAT_CONFIG")]
    config: Option<PathBuf>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the REST and gRPC APIs and the GPU workers in one process.
    Serve(ServeArgs),
    /// Run GPU workers only, sharing the database and blob store with `serve` processes (the
    /// same data dir, or `database.url` and `blobs.url` on other hosts).
    Worker(WorkerArgs),
    /// Apply the database migrations (the SQLite file, or PostgreSQL at `database.url`) and
    /// exit: what a Kubernetes Job runs before a rollout.
    Migrate(MigrateArgs),
    /// List the GPU adapters wgpu can see, as JSON.
    Adapters,
    /// Write a small synthetic COLMAP dataset (three spheres, 32 views, masks) for demos; with
    /// `--dynamic`, moving spheres as a D-NeRF dataset (one time per view).
    SyntheticScene(SyntheticSceneArgs),
    /// Train a scene locally (plain 3DGS) with a progress bar.
    Train(cli::train::TrainArgs),
    /// Render a trained scene (PLY) from a dataset's views to PNGs.
    Render(cli::render::RenderArgs),
    /// Ask a trained scene (in the service's data dir) a text query; write masks as PNGs.
    Query(cli::query::QueryArgs),
    /// Export a trained scene: PLY, labels sidecar, cameras, objects, single objects as PLY.
    Export(cli::export::ExportArgs),
    /// Score a trained scene's segmentation against LERF_OVS or 3D-OVS ground truth (mIoU).
    Eval(cli::eval::EvalArgs),
    /// Benchmark training speed and held-out quality on a dataset (JSON).
    Bench(cli::bench::BenchArgs),
    /// Measure the adapter's fp32 rate with the deformation field's GEMM kernel (JSON).
    BenchMatmul(cli::bench::matmul::MatmulArgs),
    /// Check ONNX model directories.
    Models(cli::models::ModelsArgs),
}

#[derive(Args)]
struct ServeArgs {
    /// Where the database, blobs and temporary uploads live.
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// REST listen address.
    #[arg(long = "http")]
    http_addr: Option<SocketAddr>,
    /// gRPC listen address.
    #[arg(long = "grpc")]
    grpc_addr: Option<SocketAddr>,
    /// PostgreSQL URL (`database.url`); the SQLite file in the data dir when unset.
    #[arg(long)]
    database_url: Option<String>,
    /// Serve the APIs without job workers (they run as `segsplat worker` elsewhere).
    #[arg(long)]
    api_only: bool,
}

#[derive(Args)]
struct MigrateArgs {
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// PostgreSQL URL (`database.url`); the SQLite file in the data dir when unset.
    #[arg(long)]
    database_url: Option<String>,
}

#[derive(Args)]
struct SyntheticSceneArgs {
    /// Directory to create.
    dir: PathBuf,
    #[arg(long, default_value_t = 32)]
    frames: usize,
    #[arg(long, default_value_t = 160)]
    width: u32,
    #[arg(long, default_value_t = 120)]
    height: u32,
    /// Moving, spinning spheres in the D-NeRF layout (Blender with a `time` per frame, every
    /// fourth frame held out), e.g. for `segsplat bench --deformation`.
    #[arg(long)]
    dynamic: bool,
    /// The static spheres in the Blender (NeRF-synthetic) layout: RGBA images on a transparent
    /// background, `transforms_{train,test}.json`, no sparse points.
    #[arg(long, conflicts_with = "dynamic")]
    blender: bool,
}

#[derive(Args)]
struct WorkerArgs {
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// PostgreSQL URL (`database.url`); the SQLite file in the data dir when unset.
    #[arg(long)]
    database_url: Option<String>,
}

fn main() -> ExitCode {
    quiet_display_probing();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Serve(args) => {
            let overrides = ConfigOverrides {
                data_dir: args.data_dir,
                http_addr: args.http_addr,
                grpc_addr: args.grpc_addr,
                database_url: args.database_url,
                api_only: args.api_only,
            };
            run_service(cli.config, overrides, ServiceMode::All)
        }
        Command::Worker(args) => {
            let overrides = ConfigOverrides {
                data_dir: args.data_dir,
                database_url: args.database_url,
                ..Default::default()
            };
            run_service(cli.config, overrides, ServiceMode::WorkersOnly)
        }
        Command::Migrate(args) => {
            let overrides = ConfigOverrides {
                data_dir: args.data_dir,
                database_url: args.database_url,
                ..Default::default()
            };
            init_cli_logging().and_then(|()| migrate(cli.config, overrides))
        }
        Command::Adapters => print_adapters(),
        Command::SyntheticScene(args) => write_synthetic_scene(&args),
        Command::Train(args) => init_cli_logging().and_then(|()| cli::train::run(args)),
        Command::Render(args) => init_cli_logging().and_then(|()| cli::render::run(args)),
        Command::Query(args) => init_cli_logging().and_then(|()| cli::query::run(args, cli.config)),
        Command::Export(args) => {
            init_cli_logging().and_then(|()| cli::export::run(args, cli.config))
        }
        Command::Eval(args) => init_cli_logging().and_then(|()| cli::eval::run(args, cli.config)),
        Command::Bench(args) => init_cli_logging().and_then(|()| cli::bench::run(args)),
        Command::BenchMatmul(args) => {
            init_cli_logging().and_then(|()| cli::bench::matmul::run(args))
        }
        Command::Models(args) => {
            return match init_cli_logging().and_then(|()| cli::models::run(args, cli.config)) {
                Ok(true) => ExitCode::SUCCESS,
                Ok(false) => ExitCode::FAILURE,
                Err(error) => {
                    eprintln!("segsplat models: {error:#}");
                    ExitCode::FAILURE
                }
            };
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("segsplat: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn run_service(
    config_file: Option<PathBuf>,
    overrides: ConfigOverrides,
    mode: ServiceMode,
) -> anyhow::Result<()> {
    let config = Config::load(config_file.as_deref(), std::env::vars(), &overrides)
        .context("invalid configuration")?;
    init_logging(&config)?;
    warn_about_command_kernel_variables();
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    let served = runtime.block_on(async move {
        let service = ServiceBuilder::new(config)
            .handler(std::sync::Arc::new(
                segsplat_service::job_kinds::ReconstructHandler,
            ))
            .handler(std::sync::Arc::new(
                segsplat_service::job_kinds::SegmentThenSplatHandler,
            ))
            .mode(mode)
            .start()
            .await
            .context("cannot start segsplat")?;
        service.run_until_signal().await;
        Ok(())
    });
    // Dropping a runtime waits for every blocking task, and a job's stage that did not stop
    // within the shutdown grace (its job already handed back) would hold the process until the
    // stage ended: minutes after "segsplat stopped", until Kubernetes' SIGKILL. The service has
    // stopped by now; what is left may take only a moment. Its shutdown released the GPU (every
    // device after its buffers and pipelines, crates/api/src/gpu_release.rs), so returning from
    // main exits 0 with nothing on the GPU left to the driver's exit handlers.
    runtime.shutdown_timeout(BLOCKING_WORK_AT_EXIT);
    served
}

/// `SEGSPLAT_GEMM_KERNEL` / `SEGSPLAT_RASTER_KERNEL` force kernels in the one-shot commands
/// (`train`, `bench`); the service's workers take theirs from `workers.adapters.kernels`. A
/// service started with one set would silently run the adapter's own kernels (a before/after
/// comparison of two jobs would compare a kernel with itself), so it says so.
fn warn_about_command_kernel_variables() {
    for (variable, key) in [
        (
            "SEGSPLAT_GEMM_KERNEL",
            "SEGSPLAT_WORKERS__ADAPTERS__KERNELS__GEMM",
        ),
        (
            "SEGSPLAT_RASTER_KERNEL",
            "SEGSPLAT_WORKERS__ADAPTERS__KERNELS__RASTER",
        ),
    ] {
        if std::env::var_os(variable).is_some() {
            tracing::warn!(
                "{variable} is read by the one-shot commands only and is ignored here: \
                 the service's workers take {key} (workers.adapters.kernels)"
            );
        }
    }
}

/// How long a stopped service waits for blocking work still running (a job stage that ignored
/// the stop past its grace, a blocking read) before the process exits anyway.
const BLOCKING_WORK_AT_EXIT: std::time::Duration = std::time::Duration::from_secs(2);

/// Mesa's Vulkan device-select layer connects to the Wayland display to learn which GPU drives
/// it; on a headless host that makes libwayland print `XDG_RUNTIME_DIR is invalid or not set`
/// twice on every start. segsplat picks its adapters itself (`workers.adapters`) and draws
/// nothing, so the layer is turned off (`NODEVICE_SELECT=1`) unless the environment says
/// otherwise.
#[allow(unsafe_code)]
fn quiet_display_probing() {
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: the first statement of `main`, before any thread exists, so nothing reads
        // the environment concurrently.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

fn migrate(config_file: Option<PathBuf>, overrides: ConfigOverrides) -> anyhow::Result<()> {
    let config = Config::load(config_file.as_deref(), std::env::vars(), &overrides)
        .context("invalid configuration")?;
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(async move {
        let database = segsplat_service::store::Database::connect(&config)
            .await
            .context("cannot migrate the database")?;
        println!(
            "segsplat: {} schema is up to date",
            database.backend().name()
        );
        database.close().await;
        Ok(())
    })
}

/// Logging for local commands: warnings and up unless `RUST_LOG` says otherwise, on stderr so
/// stdout stays machine-readable (`bench --json`).
fn init_cli_logging() -> anyhow::Result<()> {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init()
        .map_err(|error| anyhow::anyhow!("cannot install the logger: {error}"))
}

fn init_logging(config: &Config) -> anyhow::Result<()> {
    let filter = tracing_subscriber::EnvFilter::try_new(&config.log.level)
        .with_context(|| format!("log.level {:?}", config.log.level))?;
    // Colour only for a person at a terminal: a log redirected to a file (or NO_COLOR set)
    // gets plain text, not escape codes.
    let colour = std::io::IsTerminal::is_terminal(&std::io::stdout())
        && std::env::var_os("NO_COLOR").is_none_or(|value| value.is_empty());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(colour);
    let installed = match config.log.format {
        LogFormat::Human => builder.try_init(),
        LogFormat::Json => builder.json().try_init(),
    };
    installed.map_err(|error| anyhow::anyhow!("cannot install the logger: {error}"))
}

fn write_synthetic_scene(args: &SyntheticSceneArgs) -> anyhow::Result<()> {
    use segsplat_scene::Level;
    use segsplat_scene::synthetic::{SyntheticSpec, write_blender, write_colmap};
    use segsplat_scene::synthetic_dynamic::write_dynamic_blender;
    let spec = SyntheticSpec {
        frame_count: args.frames,
        width: args.width,
        height: args.height,
        with_masks: Some(Level::ALL.to_vec()),
        ..SyntheticSpec::default()
    };
    let (written, kind) = if args.dynamic {
        (write_dynamic_blender(&args.dir, &spec), "dynamic D-NeRF")
    } else if args.blender {
        (write_blender(&args.dir, &spec), "Blender")
    } else {
        let encoding = segsplat_scene::colmap::ColmapEncoding::Binary;
        (write_colmap(&args.dir, &spec, encoding), "COLMAP")
    };
    written.with_context(|| format!("cannot write {}", args.dir.display()))?;
    println!("wrote a synthetic {kind} dataset to {}", args.dir.display());
    Ok(())
}

fn print_adapters() -> anyhow::Result<()> {
    let reports: Vec<_> = segsplat_gpu::context::enumerate_adapters()
        .into_iter()
        .map(|(_, report)| report)
        .collect();
    println!("{}", serde_json::to_string_pretty(&reports)?);
    Ok(())
}
