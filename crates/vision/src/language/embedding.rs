//! Per-object language embeddings (docs/method.md stage 4): for every object at every level, the
//! L2-normalised mean over training views of the L2-normalised CLIP image embeddings of its
//! masked square crop (image x mask on black, cut to the mask's box, padded to a square so the
//! encoder's centre crop does not cut elongated objects).
//!
//! Views where the object's mask is empty are left out (the released code embeds them as
//! all-black crops, which pulls every object towards "black"), and so are the (view, object)
//! pairs the partial-mask filter skipped in training (an occluded sliver describes the occluder
//! as much as the object) — unless every view of an object was skipped: then its skipped views
//! are used, because an object without an embedding can never be found by a query, and a
//! partial view still describes it better than nothing (short trainings skip generously).

use std::collections::{BTreeMap, BTreeSet};

use image::RgbImage;

use crate::models::ModelError;
use crate::models::clip::{ClipImageEncoder, l2_normalise, masked_square_crop};
use segsplat_scene::Level;

#[derive(Debug, thiserror::Error)]
pub enum EmbeddingError {
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error("view {view}: image is {image:?} but its id maps have {ids} pixels")]
    SizeMismatch {
        view: usize,
        image: [u32; 2],
        ids: usize,
    },
    #[error("the image encoder answered {found} embeddings for {expected} crops")]
    EmbeddingCount { found: usize, expected: usize },
    #[error("embeddings of object {object_id} ({level:?}) differ in length: {found} vs {expected}")]
    DimensionMismatch {
        level: Level,
        object_id: u32,
        found: usize,
        expected: usize,
    },
}

/// One training view: its image at the training resolution and its row-major object-id maps
/// (small, middle, large; 0 = no object) at the same resolution.
#[derive(Debug, Clone, Copy)]
pub struct ObjectView<'a> {
    pub image: &'a RgbImage,
    pub ids: [&'a [u32]; 3],
}

/// What turns crops into unit-length embeddings; CLIP's image tower in the service, a stand-in
/// in unit tests.
pub trait CropEmbedder {
    fn embed_crops(&self, crops: &[RgbImage]) -> Result<Vec<Vec<f32>>, ModelError>;
}

impl CropEmbedder for ClipImageEncoder {
    fn embed_crops(&self, crops: &[RgbImage]) -> Result<Vec<Vec<f32>>, ModelError> {
        self.encode(crops)
    }
}

/// One object's embedding and how many views it averages.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectVector {
    pub level: Level,
    pub object_id: u32,
    pub vector: Vec<f32>,
    pub views: usize,
    /// Every view of this object was a skipped (partial) pair, so those were averaged.
    pub from_skipped_views: bool,
}

/// Sums of unit embeddings and their counts, per (level, object id).
type EmbeddingSums = BTreeMap<(Level, u32), (Vec<f32>, usize)>;

/// Running sums of per-view embeddings, so a caller can feed views one at a time (a scene's
/// training images need not all be in memory).
#[derive(Debug, Default)]
pub struct EmbeddingAccumulator {
    usable: EmbeddingSums,
    /// Sums over the skipped pairs, the fallback for objects without a usable view.
    skipped: EmbeddingSums,
}

impl EmbeddingAccumulator {
    /// Adds the crops of every object present in `view` (index `view_index`), usable and
    /// skipped apart; the crops go through the embedder together (it batches).
    pub fn add_view(
        &mut self,
        view_index: usize,
        view: &ObjectView<'_>,
        is_skipped: impl Fn(usize, Level, u32) -> bool,
        embedder: &impl CropEmbedder,
    ) -> Result<(), EmbeddingError> {
        let (keys, crops) = view_crops(view_index, view, &is_skipped)?;
        if crops.is_empty() {
            return Ok(());
        }
        let embeddings = embedder.embed_crops(&crops)?;
        if embeddings.len() != crops.len() {
            return Err(EmbeddingError::EmbeddingCount {
                found: embeddings.len(),
                expected: crops.len(),
            });
        }
        for ((level, object_id, skipped), mut embedding) in keys.into_iter().zip(embeddings) {
            l2_normalise(&mut embedding);
            let sums = if skipped {
                &mut self.skipped
            } else {
                &mut self.usable
            };
            accumulate(sums, level, object_id, &embedding)?;
        }
        Ok(())
    }

    /// Embeddings of every object seen in any view, ordered by (level, id): the mean over its
    /// usable views, or over its skipped views when it has no usable one.
    pub fn finish(self) -> Vec<ObjectVector> {
        let Self { usable, skipped } = self;
        let mut objects: BTreeMap<(Level, u32), ObjectVector> = BTreeMap::new();
        for (sums, from_skipped_views) in [(skipped, true), (usable, false)] {
            for ((level, object_id), (mut vector, views)) in sums {
                l2_normalise(&mut vector);
                // Usable views come second and replace the fallback.
                objects.insert(
                    (level, object_id),
                    ObjectVector {
                        level,
                        object_id,
                        vector,
                        views,
                        from_skipped_views,
                    },
                );
            }
        }
        objects.into_values().collect()
    }
}

/// [`EmbeddingAccumulator`] over views already in memory. `is_skipped(view, level, object_id)`
/// names the partial-mask pairs to leave out (`view` indexes `views`); `on_view_done(view)` is
/// called after each view, for progress.
pub fn object_embeddings(
    views: &[ObjectView<'_>],
    is_skipped: impl Fn(usize, Level, u32) -> bool,
    embedder: &impl CropEmbedder,
    mut on_view_done: impl FnMut(usize),
) -> Result<Vec<ObjectVector>, EmbeddingError> {
    let mut accumulator = EmbeddingAccumulator::default();
    for (view_index, view) in views.iter().enumerate() {
        accumulator.add_view(view_index, view, &is_skipped, embedder)?;
        on_view_done(view_index);
    }
    Ok(accumulator.finish())
}

/// (level, object id, whether the pair is skipped) of one crop.
type CropKey = (Level, u32, bool);

/// The masked square crops of every object present in one view, with their keys.
fn view_crops(
    view_index: usize,
    view: &ObjectView<'_>,
    is_skipped: &impl Fn(usize, Level, u32) -> bool,
) -> Result<(Vec<CropKey>, Vec<RgbImage>), EmbeddingError> {
    let (width, height) = view.image.dimensions();
    let pixels = width as usize * height as usize;
    let mut keys = Vec::new();
    let mut crops = Vec::new();
    for (level, ids) in Level::ALL.into_iter().zip(view.ids) {
        if ids.len() != pixels {
            return Err(EmbeddingError::SizeMismatch {
                view: view_index,
                image: [width, height],
                ids: ids.len(),
            });
        }
        let present: BTreeSet<u32> = ids.iter().copied().filter(|id| *id != 0).collect();
        for object_id in present {
            let mask: Vec<bool> = ids.iter().map(|id| *id == object_id).collect();
            if let Some(crop) = masked_square_crop(view.image, &mask)? {
                keys.push((level, object_id, is_skipped(view_index, level, object_id)));
                crops.push(crop);
            }
        }
    }
    Ok((keys, crops))
}

fn accumulate(
    sums: &mut EmbeddingSums,
    level: Level,
    object_id: u32,
    embedding: &[f32],
) -> Result<(), EmbeddingError> {
    let (sum, count) = sums
        .entry((level, object_id))
        .or_insert_with(|| (vec![0.0; embedding.len()], 0));
    if sum.len() != embedding.len() {
        return Err(EmbeddingError::DimensionMismatch {
            level,
            object_id,
            found: embedding.len(),
            expected: sum.len(),
        });
    }
    for (total, value) in sum.iter_mut().zip(embedding) {
        *total += value;
    }
    *count += 1;
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use super::*;

    /// Embeds a crop as its mean non-black colour, unnormalised (the code under test normalises).
    struct MeanColour {
        calls: Cell<usize>,
    }

    impl CropEmbedder for MeanColour {
        fn embed_crops(&self, crops: &[RgbImage]) -> Result<Vec<Vec<f32>>, ModelError> {
            self.calls.set(self.calls.get() + 1);
            Ok(crops
                .iter()
                .map(|crop| {
                    let mut sum = vec![0.0f32; 3];
                    for pixel in crop.pixels().filter(|p| p.0 != [0, 0, 0]) {
                        for (total, value) in sum.iter_mut().zip(pixel.0) {
                            *total += f32::from(value);
                        }
                    }
                    sum
                })
                .collect())
        }
    }

    /// A 4x2 image: left half red, right half blue; small ids 1 (left) and 2 (right), one
    /// middle object over everything, no large object.
    fn red_blue_view() -> (RgbImage, [Vec<u32>; 3]) {
        let image = RgbImage::from_fn(4, 2, |x, _| {
            if x < 2 {
                image::Rgb([200, 0, 0])
            } else {
                image::Rgb([0, 0, 200])
            }
        });
        let small = (0..8).map(|i| if i % 4 < 2 { 1 } else { 2 }).collect();
        (image, [small, vec![7; 8], vec![0; 8]])
    }

    fn views_of<'a>(items: &'a [(RgbImage, [Vec<u32>; 3])]) -> Vec<ObjectView<'a>> {
        items
            .iter()
            .map(|(image, ids)| ObjectView {
                image,
                ids: [&ids[0], &ids[1], &ids[2]],
            })
            .collect()
    }

    #[test]
    fn every_present_object_gets_a_unit_mean_and_empty_levels_none() {
        let items = [red_blue_view(), red_blue_view()];
        let embedder = MeanColour {
            calls: Cell::new(0),
        };
        let mut done = Vec::new();
        let vectors = object_embeddings(
            &views_of(&items),
            |_, _, _| false,
            &embedder,
            |view| done.push(view),
        )
        .unwrap();
        assert_eq!(done, vec![0, 1]);
        assert_eq!(embedder.calls.get(), 2, "one batch per view");
        let keys: Vec<(Level, u32, usize)> = vectors
            .iter()
            .map(|v| (v.level, v.object_id, v.views))
            .collect();
        assert_eq!(
            keys,
            vec![
                (Level::Small, 1, 2),
                (Level::Small, 2, 2),
                (Level::Middle, 7, 2)
            ]
        );
        assert!(
            (vectors[0].vector[0] - 1.0).abs() < 1e-6,
            "red object is red"
        );
        assert!(
            (vectors[1].vector[2] - 1.0).abs() < 1e-6,
            "blue object is blue"
        );
        let middle = &vectors[2].vector;
        let norm: f32 = middle.iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-6);
        assert!((middle[0] - middle[2]).abs() < 1e-6, "half red, half blue");
    }

    #[test]
    fn skipped_pairs_and_views_without_the_object_do_not_count() {
        let (image, mut ids) = red_blue_view();
        let seen = (image.clone(), ids.clone());
        // Second view: object 2 is absent at small level (all pixels object 1).
        ids[0] = vec![1; 8];
        let items = [seen, (image, ids)];
        let embedder = MeanColour {
            calls: Cell::new(0),
        };
        let vectors = object_embeddings(
            &views_of(&items),
            |view, level, id| view == 0 && level == Level::Small && id == 1,
            &embedder,
            |_| {},
        )
        .unwrap();
        let small: Vec<(u32, usize)> = vectors
            .iter()
            .filter(|v| v.level == Level::Small)
            .map(|v| (v.object_id, v.views))
            .collect();
        assert_eq!(small, vec![(1, 1), (2, 1)]);
        // Object 1 only from view 1, where it covers red and blue: a mix, not pure red.
        assert!(vectors[0].vector[2] > 0.5);
        assert!(vectors.iter().all(|v| !v.from_skipped_views));
    }

    #[test]
    fn an_object_skipped_in_every_view_falls_back_to_its_skipped_views() {
        let items = [red_blue_view(), red_blue_view()];
        let embedder = MeanColour {
            calls: Cell::new(0),
        };
        let vectors = object_embeddings(
            &views_of(&items),
            |_, level, id| level == Level::Small && id == 1,
            &embedder,
            |_| {},
        )
        .unwrap();
        let red = &vectors[0];
        assert_eq!((red.level, red.object_id, red.views), (Level::Small, 1, 2));
        assert!(red.from_skipped_views);
        assert!((red.vector[0] - 1.0).abs() < 1e-6);
        assert!(!vectors[1].from_skipped_views);
    }

    #[test]
    fn id_maps_of_the_wrong_size_are_an_error() {
        let (image, mut ids) = red_blue_view();
        ids[2] = vec![0; 3];
        let items = [(image, ids)];
        let embedder = MeanColour {
            calls: Cell::new(0),
        };
        let error =
            object_embeddings(&views_of(&items), |_, _, _| false, &embedder, |_| {}).unwrap_err();
        assert!(matches!(
            error,
            EmbeddingError::SizeMismatch { view: 0, .. }
        ));
    }
}
