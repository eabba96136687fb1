//! The models as the service holds them: loaded once at start from `[models]`, reported by
//! `/readyz`, and handed to the parts that need CLIP or SAM.

use std::path::PathBuf;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::error::ModelError;
use super::runtime::{OrtRuntime, RuntimeOptions};
use super::store::ModelStore;

/// What the service has: no model directory configured, a loaded store, or why loading failed.
#[derive(Debug, Clone)]
pub enum ModelsStatus {
    NotConfigured,
    Ready(Arc<ModelStore>),
    Failed(String),
}

impl ModelsStatus {
    /// Loads the runtime and the configured directory; never fails, the outcome is the status.
    pub fn load(config: &ModelsConfig) -> ModelsStatus {
        let Some(dir) = &config.dir else {
            return ModelsStatus::NotConfigured;
        };
        let opened = OrtRuntime::load(runtime_options(config))
            .and_then(|runtime| ModelStore::open(dir, runtime));
        match opened {
            Ok(store) => {
                tracing::info!(models = %store.summary(), "models ready");
                ModelsStatus::Ready(Arc::new(store))
            }
            Err(error) => {
                tracing::error!(%error, "models are configured but cannot be loaded");
                ModelsStatus::Failed(error.to_string())
            }
        }
    }

    /// `(ok, detail)` for `/readyz`: not configured is ready (the classical segmenter runs and
    /// text queries answer "no text encoder configured"); a failed load is not.
    pub fn readiness(&self) -> (bool, String) {
        match self {
            ModelsStatus::NotConfigured => (true, "none configured".to_string()),
            ModelsStatus::Ready(store) => (true, store.summary()),
            ModelsStatus::Failed(reason) => (false, reason.clone()),
        }
    }

    /// The store, or why there is none.
    pub fn store(&self) -> Result<&Arc<ModelStore>, ModelError> {
        match self {
            ModelsStatus::Ready(store) => Ok(store),
            ModelsStatus::NotConfigured => Err(ModelError::Input(
                "no model directory configured (models.dir)".to_string(),
            )),
            ModelsStatus::Failed(reason) => Err(ModelError::Input(format!(
                "the model directory failed to load: {reason}"
            ))),
        }
    }
}

pub fn runtime_options(config: &ModelsConfig) -> RuntimeOptions {
    RuntimeOptions {
        library: config.ort_library.clone(),
        intra_threads: config.intra_threads,
        inter_threads: config.inter_threads,
        spin_wait: config.spin_wait,
        cuda: config.cuda,
    }
}

/// ONNX models (docs/models.md). Without `dir` the service runs without learned models.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelsConfig {
    /// Model directory with `manifest.json`; unset = no models (classical segmenter, no text
    /// queries).
    pub dir: Option<PathBuf>,
    /// The ONNX Runtime shared library; unset = `ORT_DYLIB_PATH`, then the `onnxruntime` wheel.
    pub ort_library: Option<PathBuf>,
    /// Threads inside one operator; 0 = ONNX Runtime's default.
    pub intra_threads: usize,
    /// Threads across operators; 0 = ONNX Runtime's default.
    pub inter_threads: usize,
    /// Let ONNX Runtime's threads spin-wait between operators (its own default). Off here: a
    /// worker's models share the machine with training (on a CPU adapter, training is the CPU)
    /// and with the classical masks, which a spinning thread would slow for a few percent less
    /// latency per answer.
    pub spin_wait: bool,
    /// Use the CUDA execution provider when the library and a GPU offer it (on by default; the
    /// CPU otherwise). `false` keeps models on the CPU even where CUDA is available.
    pub cuda: bool,
}

impl Default for ModelsConfig {
    fn default() -> Self {
        Self {
            dir: None,
            ort_library: None,
            intra_threads: 0,
            inter_threads: 0,
            spin_wait: false,
            cuda: true,
        }
    }
}
