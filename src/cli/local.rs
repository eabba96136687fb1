//! The service's stores, opened from a local command: the same config layering as `serve`
//! (file, `SEGSPLAT_*`, `--data-dir`), the database and blob dir, the models, and the serving
//! core, so `query`, `export` and `eval` answer exactly what the service would.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use clap::Args;
use segsplat_service::config::{Config, ConfigOverrides};
use segsplat_service::core::ServiceCore;
use segsplat_service::jobs::{HandlerRegistry, JobEventBus};
use segsplat_service::store::{Caller, Database, open_blob_store};
use segsplat_service::usecases::scenes::{self, SceneFailure};
use segsplat_service::usecases::serving::Serving;
use segsplat_vision::language::SharedTextEncoder;
use segsplat_vision::models::ModelsStatus;

/// Where the service keeps its data.
#[derive(Args, Debug, Clone)]
pub struct StoreArgs {
    /// The service's data dir (database and blobs); default from the config, `./data`.
    #[arg(long)]
    pub data_dir: Option<PathBuf>,
}

/// The service core a local command calls its use cases with. It queues no jobs: the job
/// kinds are empty and no worker listens.
pub struct LocalService {
    pub core: ServiceCore,
}

impl LocalService {
    /// Opens the stores without loading models (exports need none).
    pub async fn open(config_file: Option<&Path>, store: &StoreArgs) -> anyhow::Result<Self> {
        Self::open_with(config_file, store, false).await
    }

    /// Opens the stores and loads the configured models (text queries).
    pub async fn open_with_models(
        config_file: Option<&Path>,
        store: &StoreArgs,
    ) -> anyhow::Result<Self> {
        Self::open_with(config_file, store, true).await
    }

    async fn open_with(
        config_file: Option<&Path>,
        store: &StoreArgs,
        models: bool,
    ) -> anyhow::Result<Self> {
        let overrides = ConfigOverrides {
            data_dir: store.data_dir.clone(),
            ..Default::default()
        };
        let config = Config::load(config_file, std::env::vars(), &overrides)
            .context("invalid configuration")?;
        let database = match &config.database.url {
            Some(_) => Database::connect(&config)
                .await
                .context("cannot open the PostgreSQL database of database.url")?,
            None => {
                let database_path = config.database_path();
                if !database_path.exists() {
                    anyhow::bail!(
                        "no segsplat database at {} (pass --data-dir, the folder `segsplat serve` \
                         uses, or set database.url)",
                        database_path.display()
                    );
                }
                Database::open(&database_path)
                    .await
                    .with_context(|| format!("cannot open {}", database_path.display()))?
            }
        };
        let blobs = open_blob_store(&config).context("cannot open the blob store")?;
        let models_status = if models {
            let models_config = config.models.clone();
            tokio::task::spawn_blocking(move || ModelsStatus::load(&models_config))
                .await
                .context("model loading crashed")?
        } else {
            ModelsStatus::NotConfigured
        };
        let serving = Serving::from_config(&config, database.clone(), blobs.clone());
        Ok(Self {
            core: ServiceCore {
                config: Arc::new(config),
                database,
                blobs,
                handlers: HandlerRegistry::default(),
                bus: JobEventBus::default(),
                job_queued: Arc::default(),
                adapters: Arc::new([]),
                text_encoder: Arc::new(SharedTextEncoder::new(Arc::new(models_status))),
                serving,
            },
        })
    }

    /// The scene's id from an id or a unique scene name.
    pub async fn resolve_scene(&self, id_or_name: &str) -> anyhow::Result<String> {
        let system = Caller::system();
        match scenes::get_scene(&self.core, &system, id_or_name).await {
            Ok(scene) => return Ok(scene.id),
            Err(SceneFailure::NotFound(_)) => {}
            Err(failure) => return Err(failure.into()),
        }
        let named: Vec<String> = scenes::list_scenes(&self.core, &system)
            .await?
            .into_iter()
            .filter(|scene| scene.name == id_or_name)
            .map(|scene| scene.id)
            .collect();
        match named.as_slice() {
            [id] => Ok(id.clone()),
            [] => anyhow::bail!("no scene with id or name {id_or_name:?}"),
            ids => anyhow::bail!(
                "{} scenes are named {id_or_name:?}; use an id: {}",
                ids.len(),
                ids.join(", ")
            ),
        }
    }
}
