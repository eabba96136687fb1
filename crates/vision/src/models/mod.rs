//! models: ONNX Runtime sessions (`ort`, library loaded at run time), the model store (manifest,
//! hashes, signatures), CLIP (tokenizer, preprocessing, image/text encoders) and the SAM-family
//! prompt driver. The directory contract is docs/models.md.

pub mod clip;
pub mod clip_pair;
pub mod error;
pub mod init;
pub mod manifest;
pub mod recognise;
pub mod reference_check;
pub mod resample;
pub mod runtime;
pub mod sam;
pub mod service;
pub mod session;
pub mod signature;
pub mod store;

pub use error::ModelError;
pub use manifest::{Manifest, ModelEntry, Role};
pub use runtime::{OrtRuntime, RuntimeOptions};
pub use service::{ModelsConfig, ModelsStatus};
pub use session::ModelSession;
pub use store::{DirectoryCheck, ModelStore};
