//! Starting and stopping the service: database, blob store, GPU workers, lease reaper, and the
//! REST and gRPC listeners, with a graceful shutdown that finishes in-flight requests and hands
//! running jobs back to the queue.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use futures::future::BoxFuture;
use tokio::net::TcpListener;
use tokio::sync::Notify;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};

use super::auth::{TokenCheck, grpc_interceptor};
use super::gpu_release::release_gpus;
use super::grpc::SceneQueryService;
use super::grpc_calls::GrpcCallLayer;
use super::metrics::{prometheus_handle, register_zero_series};
use super::router::{ops_router, router};
use super::state::{AppState, WorkerReadiness};
use crate::proto::scene_query_server::SceneQueryServer;
use segsplat_service::config::Config;
use segsplat_service::core::ServiceCore;
use segsplat_service::jobs::{
    HandlerRegistry, JobEventBus, JobHandler, LeaseReaper, ProcessIdentity, SweepPlaces,
    WorkerPool, WorkerPoolOptions, WorkerSlot, forward_remote_wakeups, open_adapters,
    sweep_leftovers,
};
use segsplat_service::store::blob_deletions::run_blob_deletion_sweeps;
use segsplat_service::store::{BlobStore, Database, StoreError, open_blob_store};
use segsplat_service::usecases::serving::Serving;
use segsplat_vision::language::SharedTextEncoder;

#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("blob store: {0}")]
    Blob(#[from] segsplat_service::store::BlobError),
    #[error("cannot create {path}: {source}")]
    CreateDir {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot listen on {addr} ({what}): {source}")]
    Bind {
        addr: SocketAddr,
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("metrics recorder: another recorder is already installed in this process")]
    Metrics,
    #[error("gRPC reflection: {0}")]
    Reflection(String),
    #[error("GPU discovery crashed: {0}")]
    GpuDiscovery(String),
}

/// Which parts run in this process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceMode {
    /// REST + gRPC + workers (`segsplat serve`).
    All,
    /// Workers and the lease reaper only (`segsplat worker`).
    WorkersOnly,
}

pub struct ServiceBuilder {
    config: Config,
    handlers: HandlerRegistry,
    mode: ServiceMode,
    detect_gpus: bool,
}

impl ServiceBuilder {
    pub fn new(config: Config) -> Self {
        Self {
            config,
            handlers: HandlerRegistry::default(),
            mode: ServiceMode::All,
            detect_gpus: true,
        }
    }

    /// Registers a job kind.
    pub fn handler(mut self, handler: Arc<dyn JobHandler>) -> Self {
        self.handlers.register(handler);
        self
    }

    pub fn mode(mut self, mode: ServiceMode) -> Self {
        self.mode = mode;
        self
    }

    /// Skips GPU discovery (tests exercising the queue with CPU-only slots).
    pub fn detect_gpus(mut self, detect: bool) -> Self {
        self.detect_gpus = detect;
        self
    }

    /// Starts everything and returns once both listeners are bound.
    ///
    /// A boxed future rather than an `async fn`: an async fn's body is compiled in every crate
    /// that awaits it, and this one pulls in the whole server (axum, tonic, hyper, sqlx): a test
    /// binary that only starts and stops a service took 27 s of CPU to compile, 4 s boxed. Boxed
    /// here, it is compiled once, in this crate.
    pub fn start(self) -> BoxFuture<'static, Result<RunningService, ServiceError>> {
        Box::pin(self.start_unboxed())
    }

    async fn start_unboxed(self) -> Result<RunningService, ServiceError> {
        let config = Arc::new(self.config);
        for dir in [config.data_dir.clone(), config.scratch_dir()] {
            std::fs::create_dir_all(&dir).map_err(|source| ServiceError::CreateDir {
                path: dir.display().to_string(),
                source,
            })?;
        }
        let database = Database::connect(&config).await?;
        let blobs = open_blob_store(&config)?;
        let metrics = prometheus_handle().ok_or(ServiceError::Metrics)?;
        register_zero_series(&self.handlers.kinds());
        let bus = JobEventBus::default();
        let job_queued = Arc::new(Notify::new());
        let shutdown = CancellationToken::new();
        let identity = ProcessIdentity::new(config.workers.instance_id.clone());
        let instance = identity.instance().to_string();
        // Jobs a previous life of this process (or a stopped process on this host) held are
        // re-queued now rather than after their leases run out. A process without workers is
        // not the one that held its instance id's leases (an API process sharing a config file
        // with a worker), so it only takes back those of exited processes.
        let workers_here = config.workers.enabled;
        match database
            .requeue_leases_of_gone_owners(|owner| {
                if workers_here {
                    identity.owned_by_a_previous_life(owner)
                } else {
                    identity.owned_by_a_stopped_local_process(owner)
                }
            })
            .await
        {
            Ok(taken) => {
                for lease in &taken {
                    info!(job_id = %lease.job_id, owner = ?lease.previous_owner,
                        state = lease.new_state.as_str(), "took back a stopped worker's job");
                }
            }
            Err(error) => warn!(%error, "cannot take back stopped workers' jobs"),
        }
        // After taking jobs back, so their attempt folders count as stale.
        let places = SweepPlaces {
            scratch_dir: config.scratch_dir(),
            blob_dir: config.blob_dir(),
            scene_cache_dir: config.scene_cache_dir(),
            max_age: Duration::from_secs(config.storage.temp_max_age_secs),
        };
        sweep_leftovers(&places, &database).await;

        let workers_enabled = config.workers.enabled;
        let (gpus, mut problems) = if workers_enabled && self.detect_gpus {
            let filter = config.workers.adapters.clone();
            tokio::task::spawn_blocking(move || open_adapters(&filter))
                .await
                .map_err(|error| ServiceError::GpuDiscovery(error.to_string()))?
        } else {
            (Vec::new(), Vec::new())
        };
        if workers_enabled && !self.detect_gpus {
            problems.push("GPU discovery is disabled".to_string());
        }
        for problem in &problems {
            warn!(%problem, "GPU workers unavailable");
        }
        let mut slots = Vec::new();
        if workers_enabled {
            for gpu in &gpus {
                for _ in 0..config.workers.slots_per_adapter {
                    slots.push(WorkerSlot {
                        gpu: Some(gpu.clone()),
                    });
                }
            }
            for _ in 0..config.workers.cpu_slots {
                slots.push(WorkerSlot { gpu: None });
            }
        }
        let readiness = WorkerReadiness {
            enabled: workers_enabled,
            gpu_slots: slots.iter().filter(|slot| slot.gpu.is_some()).count(),
            cpu_slots: slots.iter().filter(|slot| slot.gpu.is_none()).count(),
            adapters: gpus.iter().map(|gpu| gpu.report.clone()).collect(),
            problems,
        };
        crate::metrics::record_build_info(
            readiness
                .adapters
                .first()
                .map_or("none", |adapter| adapter.name.as_str()),
        );

        tokio::spawn(run_blob_deletion_sweeps(
            database.clone(),
            blobs.clone(),
            shutdown.clone(),
        ));
        spawn_periodic_sweep(
            places,
            database.clone(),
            Duration::from_secs(config.storage.sweep_interval_secs),
            shutdown.clone(),
        );
        let lease = Duration::from_secs_f64(config.jobs.lease_secs);
        let reaper = LeaseReaper::start(
            database.clone(),
            identity.clone(),
            bus.clone(),
            job_queued.clone(),
            (lease / 4).clamp(Duration::from_millis(50), Duration::from_secs(5)),
            lease,
        );
        // Ends with `shutdown`; on SQLite there is nothing to listen to.
        let _wakeups =
            forward_remote_wakeups(&database, bus.clone(), job_queued.clone(), shutdown.clone())
                .await;
        // Loaded before the workers start: jobs embed objects with CLIP.
        let models_config = config.models.clone();
        let models = Arc::new(
            tokio::task::spawn_blocking(move || {
                segsplat_vision::models::ModelsStatus::load(&models_config)
            })
            .await
            .unwrap_or_else(|error| {
                segsplat_vision::models::ModelsStatus::Failed(format!(
                    "model loading panicked: {error}"
                ))
            }),
        );
        let text_encoder = Arc::new(SharedTextEncoder::new(models.clone()));
        let serving = Serving::from_config(&config, database.clone(), blobs.clone());
        let pool = (!slots.is_empty()).then(|| {
            WorkerPool::start(WorkerPoolOptions {
                database: database.clone(),
                blobs: blobs.clone(),
                models: models.clone(),
                handlers: self.handlers.clone(),
                bus: bus.clone(),
                jobs: config.jobs.clone(),
                scratch_dir: config.scratch_dir(),
                scene_cache_dir: config.scene_cache_dir(),
                scene_cache_bytes: config.blobs.worker_cache_mib << 20,
                slots,
                job_queued: job_queued.clone(),
                instance: instance.clone(),
                shutdown_grace: lease,
            })
        });

        let core = ServiceCore {
            config: config.clone(),
            database: database.clone(),
            blobs,
            handlers: self.handlers,
            bus,
            job_queued,
            adapters: readiness.adapters.clone().into(),
            text_encoder,
            serving,
        };
        let state = AppState {
            core: core.clone(),
            workers: Arc::new(readiness),
            models,
            metrics,
            shutdown: shutdown.clone(),
            readiness: Default::default(),
        };
        let (http, grpc) = match self.mode {
            ServiceMode::All => {
                let http = start_http(config.http_addr, router(state.clone()), &shutdown).await?;
                let grpc = start_grpc(&config, core, shutdown.clone()).await?;
                (Some(http), Some(grpc))
            }
            ServiceMode::WorkersOnly => {
                let ops_addr = config.workers.ops_addr;
                let http = start_http(ops_addr, ops_router(state.clone()), &shutdown).await?;
                (Some(http), None)
            }
        };
        info!(instance = %instance, http = ?http.as_ref().map(|s| s.0),
            grpc = ?grpc.as_ref().map(|s| s.0), "segsplat started");
        Ok(RunningService {
            http,
            grpc,
            shutdown,
            pool,
            reaper,
            database,
            state,
        })
    }
}

async fn start_http(
    bind: SocketAddr,
    app: axum::Router,
    shutdown: &CancellationToken,
) -> Result<(SocketAddr, JoinHandle<()>), ServiceError> {
    let bind_error = |source| ServiceError::Bind {
        addr: bind,
        what: "HTTP",
        source,
    };
    let listener = TcpListener::bind(bind).await.map_err(bind_error)?;
    let addr = listener.local_addr().map_err(bind_error)?;
    let shutdown = shutdown.clone();
    let task = tokio::spawn(async move {
        // Small replies go out at once instead of waiting on Nagle's algorithm for the
        // client's delayed ACK (a 20-40 ms floor on every small response).
        let listener = axum::serve::ListenerExt::tap_io(listener, |tcp| {
            if let Err(error) = tcp.set_nodelay(true) {
                warn!(%error, "cannot set TCP_NODELAY on an HTTP connection");
            }
        });
        let served = axum::serve(listener, app)
            .with_graceful_shutdown(async move { shutdown.cancelled().await })
            .await;
        if let Err(error) = served {
            warn!(%error, "HTTP server stopped with an error");
        }
    });
    Ok((addr, task))
}

async fn start_grpc(
    config: &Config,
    core: ServiceCore,
    shutdown: CancellationToken,
) -> Result<(SocketAddr, JoinHandle<()>), ServiceError> {
    let listener = TcpListener::bind(config.grpc_addr)
        .await
        .map_err(|source| ServiceError::Bind {
            addr: config.grpc_addr,
            what: "gRPC",
            source,
        })?;
    let addr = listener.local_addr().map_err(|source| ServiceError::Bind {
        addr: config.grpc_addr,
        what: "gRPC",
        source,
    })?;
    let tokens = TokenCheck::from_config(&config.auth);
    let (health_reporter, health_service) = tonic_health::server::health_reporter();
    health_reporter
        .set_serving::<SceneQueryServer<SceneQueryService>>()
        .await;
    // Both reflection versions: `grpc.reflection.v1`, and `v1alpha`, which grpcio's reflection
    // client, grpcurl's older releases and many tools still speak; our own service
    // (`grpc_reflection.rs`), which answers an unknown name inside the stream. Open, like
    // health: reflection describes the API's services and messages (the proto file), never a
    // tenant's data, and grpcurl resolves every call through it, a health check included.
    let descriptors = crate::grpc_reflection::api_descriptors()
        .map_err(|error| ServiceError::Reflection(error.to_string()))?;
    let reflection = crate::grpc_reflection::v1::server(Arc::clone(&descriptors));
    let reflection_v1alpha = crate::grpc_reflection::v1alpha::server(descriptors);
    let scene_query =
        SceneQueryServer::with_interceptor(SceneQueryService::new(core), grpc_interceptor(tokens));
    let task = tokio::spawn(async move {
        let served = tonic::transport::Server::builder()
            .trace_fn(|request| tracing::info_span!("grpc", path = %request.uri().path()))
            .layer(GrpcCallLayer)
            .add_service(health_service)
            .add_service(reflection)
            .add_service(reflection_v1alpha)
            .add_service(scene_query)
            .serve_with_incoming_shutdown(
                // As for HTTP: no Nagle delay on small replies.
                tokio_stream::StreamExt::map(
                    tokio_stream::wrappers::TcpListenerStream::new(listener),
                    |accepted| {
                        if let Ok(tcp) = &accepted
                            && let Err(error) = tcp.set_nodelay(true)
                        {
                            warn!(%error, "cannot set TCP_NODELAY on a gRPC connection");
                        }
                        accepted
                    },
                ),
                async move { shutdown.cancelled().await },
            )
            .await;
        if let Err(error) = served {
            warn!(%error, "gRPC server stopped with an error");
        }
    });
    Ok((addr, task))
}

/// Sweeps leftovers of stopped processes every `every` until `shutdown`.
fn spawn_periodic_sweep(
    places: SweepPlaces,
    database: Database,
    every: Duration,
    shutdown: CancellationToken,
) {
    tokio::spawn(async move {
        let mut ticker = tokio::time::interval(every);
        // The first tick is immediate, and the sweep at start already ran.
        ticker.tick().await;
        loop {
            tokio::select! {
                _ = ticker.tick() => { sweep_leftovers(&places, &database).await; }
                _ = shutdown.cancelled() => break,
            }
        }
    });
}

/// A started service; stop it with [`RunningService::shutdown`].
pub struct RunningService {
    http: Option<(SocketAddr, JoinHandle<()>)>,
    grpc: Option<(SocketAddr, JoinHandle<()>)>,
    shutdown: CancellationToken,
    pool: Option<WorkerPool>,
    reaper: LeaseReaper,
    database: Database,
    state: AppState,
}

impl RunningService {
    /// The bound REST address (the real port when the config asked for port 0).
    pub fn http_addr(&self) -> Option<SocketAddr> {
        self.http.as_ref().map(|(addr, _)| *addr)
    }

    pub fn grpc_addr(&self) -> Option<SocketAddr> {
        self.grpc.as_ref().map(|(addr, _)| *addr)
    }

    pub fn database(&self) -> &Database {
        &self.database
    }

    pub fn blobs(&self) -> Arc<dyn BlobStore> {
        self.state.core.blobs.clone()
    }

    /// The core the REST and gRPC listeners call, for embedding callers (the console, tests)
    /// that use the use cases without going through HTTP.
    pub fn core(&self) -> &ServiceCore {
        &self.state.core
    }

    /// Loads and hits of the GPU scene cache masks are rendered from.
    pub fn serving_stats(&self) -> segsplat_service::serving::CacheStats {
        self.state.core.serving.cache().stats()
    }

    /// Runs until SIGINT or SIGTERM, then shuts down gracefully.
    pub async fn run_until_signal(self) {
        wait_for_signal().await;
        info!("shutdown requested");
        self.shutdown().await;
    }

    /// Stops listening (in-flight requests finish), hands running jobs back to the queue,
    /// releases the GPU (mask renderer, then the workers' devices: [`release_gpus`]), and closes
    /// the database.
    ///
    /// Boxed for the reason [`ServiceBuilder::start`] is.
    pub fn shutdown(self) -> BoxFuture<'static, ()> {
        Box::pin(self.shutdown_unboxed())
    }

    async fn shutdown_unboxed(self) {
        self.shutdown.cancel();
        for (_, task) in self.http.into_iter().chain(self.grpc) {
            if let Err(error) = task.await {
                warn!(%error, "server task ended abnormally");
            }
        }
        let worker_gpus = match self.pool {
            Some(pool) => pool.shutdown().await,
            None => Vec::new(),
        };
        self.reaper.shutdown().await;
        // After the listeners (no render starts) and the workers (jobs handed back), before
        // "segsplat stopped": nothing on the GPU is left for the process's exit.
        release_gpus(&self.state.core, worker_gpus).await;
        self.database.close().await;
        info!("segsplat stopped");
    }
}

async fn wait_for_signal() {
    let interrupt = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut terminate) => {
                tokio::select! {
                    _ = interrupt => {}
                    _ = terminate.recv() => {}
                }
            }
            Err(error) => {
                warn!(%error, "cannot listen for SIGTERM; only Ctrl-C stops the service");
                let _ = interrupt.await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = interrupt.await;
    }
}
