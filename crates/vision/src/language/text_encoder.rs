//! The service's one CLIP text encoder, built on first use and shared by every query (REST and
//! gRPC), so its session and its cache of text embeddings live as long as the service.

use std::sync::{Arc, OnceLock};

use crate::models::clip::{ClipTextEncoder, DEFAULT_TEXT_CACHE_ENTRIES};
use crate::models::{ModelsStatus, Role};

/// Why queries cannot be answered by text.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TextEncoderUnavailable {
    #[error("no text encoder configured (models.dir has no clip_text model)")]
    NotConfigured,
    #[error("the text encoder cannot be used: {0}")]
    Failed(String),
}

/// The lazily built encoder plus the name of the image model whose embeddings it is compared
/// with (stored embeddings carry that name as their model id).
pub struct SharedTextEncoder {
    models: Arc<ModelsStatus>,
    encoder: OnceLock<Result<Arc<ClipTextEncoder>, TextEncoderUnavailable>>,
}

impl SharedTextEncoder {
    pub fn new(models: Arc<ModelsStatus>) -> Self {
        Self {
            models,
            encoder: OnceLock::new(),
        }
    }

    /// The encoder, built once (blocking: opens an ONNX session; call from `spawn_blocking`).
    /// A failed build is remembered too, so a broken model is not reopened per request.
    pub fn encoder(&self) -> Result<Arc<ClipTextEncoder>, TextEncoderUnavailable> {
        self.encoder
            .get_or_init(|| {
                let store = match self.models.as_ref() {
                    ModelsStatus::NotConfigured => {
                        return Err(TextEncoderUnavailable::NotConfigured);
                    }
                    ModelsStatus::Failed(reason) => {
                        return Err(TextEncoderUnavailable::Failed(reason.clone()));
                    }
                    ModelsStatus::Ready(store) => store,
                };
                if !store.has(Role::ClipText) {
                    return Err(TextEncoderUnavailable::NotConfigured);
                }
                ClipTextEncoder::new(store, DEFAULT_TEXT_CACHE_ENTRIES)
                    .map(Arc::new)
                    .map_err(|error| TextEncoderUnavailable::Failed(error.to_string()))
            })
            .clone()
    }

    /// The model id object embeddings are stored under: the manifest name of the CLIP image
    /// model, `None` when there is none.
    pub fn image_model_id(&self) -> Option<String> {
        image_model_id(&self.models)
    }
}

/// The manifest name of the configured CLIP image model, the `model_id` of stored embeddings.
pub fn image_model_id(models: &ModelsStatus) -> Option<String> {
    match models {
        ModelsStatus::Ready(store) => store
            .manifest()
            .model(Role::ClipImage)
            .map(|entry| entry.name.clone()),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_models_queries_hear_not_configured() {
        let shared = SharedTextEncoder::new(Arc::new(ModelsStatus::NotConfigured));
        assert_eq!(
            shared.encoder().err(),
            Some(TextEncoderUnavailable::NotConfigured)
        );
        assert_eq!(shared.image_model_id(), None);
        let failed = SharedTextEncoder::new(Arc::new(ModelsStatus::Failed("bad".to_string())));
        assert!(matches!(
            failed.encoder().err(),
            Some(TextEncoderUnavailable::Failed(_))
        ));
    }
}
