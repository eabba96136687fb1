//! CLIP image and text encoders over the model store: batched, L2-normalised embeddings, and an
//! LRU cache of text embeddings (queries repeat).

use std::num::NonZeroUsize;
use std::sync::{Arc, Mutex};

use image::RgbImage;
use lru::LruCache;

use super::preprocess::clip_pixel_values;
use super::tokenizer::ClipTokenizer;
use crate::models::error::ModelError;
use crate::models::manifest::{ClipImagePreprocess, Preprocess, Role};
use crate::models::session::{InputTensor, ModelSession};
use crate::models::store::ModelStore;

/// Images or texts per model run: bounds memory (a 336 px image is 1.3 MB of input).
pub const DEFAULT_BATCH_SIZE: usize = 16;
/// Text embeddings kept by default.
pub const DEFAULT_TEXT_CACHE_ENTRIES: usize = 4096;

/// Scales `vector` to unit length (a zero vector stays zero).
pub fn l2_normalise(vector: &mut [f32]) {
    let norm = vector.iter().map(|value| value * value).sum::<f32>().sqrt();
    if norm > 0.0 {
        for value in vector {
            *value /= norm;
        }
    }
}

/// Splits a `[N, D]` output into N normalised rows.
fn normalised_rows(
    model: &str,
    shape: &[usize],
    data: Vec<f32>,
    expected_rows: usize,
) -> Result<Vec<Vec<f32>>, ModelError> {
    let [rows, width] = shape else {
        return Err(ModelError::Output {
            model: model.to_string(),
            reason: format!("embeddings have shape {shape:?}, expected [N, D]"),
        });
    };
    if *rows != expected_rows || *width == 0 {
        return Err(ModelError::Output {
            model: model.to_string(),
            reason: format!("embeddings have shape {shape:?} for {expected_rows} inputs"),
        });
    }
    Ok(data
        .chunks_exact(*width)
        .map(|row| {
            let mut row = row.to_vec();
            l2_normalise(&mut row);
            row
        })
        .collect())
}

/// Text embeddings by (model name, text): one cache may outlive a model swap.
type TextEmbeddingCache = LruCache<(String, String), Arc<[f32]>>;

pub struct ClipTextEncoder {
    session: Arc<ModelSession>,
    tokenizer: Arc<ClipTokenizer>,
    batch_size: usize,
    cache: Mutex<TextEmbeddingCache>,
}

impl ClipTextEncoder {
    pub fn new(store: &ModelStore, cache_entries: usize) -> Result<ClipTextEncoder, ModelError> {
        let session = store.session(Role::ClipText)?;
        let tokenizer = store.tokenizer()?;
        if let Preprocess::ClipText(preprocess) = &session.entry().preprocess
            && preprocess.context_length != tokenizer.context_length()
        {
            return Err(ModelError::Input(format!(
                "clip_text {} expects context_length {}, the tokenizer pads to {}",
                session.entry().name,
                preprocess.context_length,
                tokenizer.context_length()
            )));
        }
        let capacity = NonZeroUsize::new(cache_entries).unwrap_or(NonZeroUsize::MIN);
        Ok(ClipTextEncoder {
            session,
            tokenizer,
            batch_size: DEFAULT_BATCH_SIZE,
            cache: Mutex::new(LruCache::new(capacity)),
        })
    }

    pub fn model_name(&self) -> &str {
        &self.session.entry().name
    }

    pub fn tokenizer(&self) -> &ClipTokenizer {
        &self.tokenizer
    }

    /// Unit-length embeddings of `texts`, in order; cached texts skip the model.
    pub fn encode(&self, texts: &[&str]) -> Result<Vec<Arc<[f32]>>, ModelError> {
        let model = self.model_name().to_string();
        let mut results: Vec<Option<Arc<[f32]>>> = {
            let mut cache = self
                .cache
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner());
            texts
                .iter()
                .map(|text| cache.get(&(model.clone(), (*text).to_string())).cloned())
                .collect()
        };
        let missing: Vec<usize> = (0..texts.len())
            .filter(|index| results[*index].is_none())
            .collect();
        for chunk in missing.chunks(self.batch_size) {
            let chunk_texts: Vec<&str> = chunk.iter().map(|index| texts[*index]).collect();
            let embeddings = self.encode_uncached(&chunk_texts)?;
            let mut cache = self
                .cache
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner());
            for (index, embedding) in chunk.iter().zip(embeddings) {
                let embedding: Arc<[f32]> = embedding.into();
                cache.put(
                    (model.clone(), texts[*index].to_string()),
                    embedding.clone(),
                );
                results[*index] = Some(embedding);
            }
        }
        results
            .into_iter()
            .map(|result| {
                result.ok_or_else(|| ModelError::Output {
                    model: model.clone(),
                    reason: "a text was not encoded".to_string(),
                })
            })
            .collect()
    }

    fn encode_uncached(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, ModelError> {
        let ids = self.tokenizer.encode_batch(texts)?;
        let shape = [texts.len(), self.tokenizer.context_length()];
        let mut outputs = self.session.run(
            &[(
                "input_ids",
                InputTensor::I64 {
                    shape: &shape,
                    data: &ids,
                },
            )],
            &["text_embeds"],
        )?;
        let output = outputs.remove(0);
        normalised_rows(self.model_name(), &output.shape, output.data, texts.len())
    }
}

pub struct ClipImageEncoder {
    session: Arc<ModelSession>,
    preprocess: ClipImagePreprocess,
    batch_size: usize,
}

impl ClipImageEncoder {
    pub fn new(store: &ModelStore) -> Result<ClipImageEncoder, ModelError> {
        let session = store.session(Role::ClipImage)?;
        let Preprocess::ClipImage(preprocess) = session.entry().preprocess.clone() else {
            return Err(ModelError::Input(format!(
                "clip_image {} has no image preprocessing",
                session.entry().name
            )));
        };
        Ok(ClipImageEncoder {
            session,
            preprocess,
            batch_size: DEFAULT_BATCH_SIZE,
        })
    }

    pub fn model_name(&self) -> &str {
        &self.session.entry().name
    }

    pub fn preprocess(&self) -> &ClipImagePreprocess {
        &self.preprocess
    }

    /// Unit-length embeddings of `images` (any sizes), in order, `batch_size` per model run.
    pub fn encode(&self, images: &[RgbImage]) -> Result<Vec<Vec<f32>>, ModelError> {
        let mut embeddings = Vec::with_capacity(images.len());
        for chunk in images.chunks(self.batch_size) {
            let mut pixels = Vec::new();
            for image in chunk {
                pixels.extend(clip_pixel_values(image, &self.preprocess));
            }
            embeddings.extend(self.encode_pixel_values(&pixels, chunk.len())?);
        }
        Ok(embeddings)
    }

    /// Embeddings of already preprocessed `count x 3 x R x R` pixel values.
    pub fn encode_pixel_values(
        &self,
        pixel_values: &[f32],
        count: usize,
    ) -> Result<Vec<Vec<f32>>, ModelError> {
        let size = self.preprocess.image_size as usize;
        if pixel_values.len() != count * 3 * size * size {
            return Err(ModelError::Input(format!(
                "{} pixel values for {count} images of 3 x {size} x {size}",
                pixel_values.len()
            )));
        }
        let shape = [count, 3, size, size];
        let mut outputs = self.session.run(
            &[(
                "pixel_values",
                InputTensor::F32 {
                    shape: &shape,
                    data: pixel_values,
                },
            )],
            &["image_embeds"],
        )?;
        let output = outputs.remove(0);
        normalised_rows(self.model_name(), &output.shape, output.data, count)
    }
}
