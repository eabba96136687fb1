//! The Segment-then-Splat object loss (docs/method.md, stage 3): every step, for each active level,
//! `m` objects present in the view's masks are rendered alone (only their Gaussians, on black)
//! and compared with `image x mask` by the same fused L1 + D-SSIM loss as the full render. The
//! levels join coarse-ward in stages (small; + middle; + large), and near the end of training the
//! (object, view) pairs whose render disagrees with the mask (IoU < 0.3: the 2D mask is a partial,
//! occluded view) are left out and recorded, so the language stage can skip them too.

use rand::Rng;
use rand::seq::IndexedRandom;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use std::collections::BTreeSet;

use crate::OBJECT_NONE;
use crate::loss::object_cell_map;
use segsplat_gpu::GpuContext;
use segsplat_scene::Level;
use segsplat_scene::id_runs::id_pixel_counts;

/// When and how strongly the object loss acts. Stage boundaries are fractions of the run's
/// steps so one config serves short and long runs (released: 5k / 5k / rest of 40k).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ObjectLossConfig {
    /// Objects rendered per active level per step (`m`; paper: 3, 1 for small scenes).
    pub objects_per_level: u32,
    /// Weight of each object render's loss, relative to the full render's.
    pub weight: f32,
    /// Fraction of the steps after which the middle level joins the small one.
    pub middle_from: f32,
    /// Fraction of the steps after which the large level joins.
    pub large_from: f32,
    /// Fraction of the laid-out steps (`TrainConfig::schedule_steps`, else the steps) from which
    /// partial masks are filtered (released: 30k of 40k). 1.0 filters after the last of them:
    /// the left-out pairs then only leave the embeddings.
    pub partial_filter_from: f32,
    /// An (object, view) pair whose rendered mask (alpha > 0.5) has IoU below this with the
    /// 2D mask is skipped from then on.
    pub partial_iou_threshold: f32,
    /// Draw only objects that own Gaussians (when the masks were attached). An object of the
    /// masks with none renders nothing, so its draw trains nothing; on the figurine 59% of
    /// the (object, view) pairs are such objects (docs/segment_then_splat.md). `false` draws
    /// from every object of the view's masks, as the released code does.
    pub only_objects_with_gaussians: bool,
    /// From this step the weight falls linearly, reaching 0 as many steps later (twice this
    /// step); `None` keeps the full weight to the end (the released code). A
    /// `segment_then_splat` job that leaves it out fades from its scene-sized steps, so a job
    /// of the default length keeps the full weight and a longer one stops pulling each
    /// object's Gaussians towards its masks once the scene is fit: on the figurine the object
    /// loss kept on for twice the steps cost up to 1.3 dB of held-out PSNR, and without it
    /// held-out PSNR rose to the end (docs/segment_then_splat.md, "Longer than the scene
    /// needs").
    pub fade_from_step: Option<u32>,
}

impl Default for ObjectLossConfig {
    fn default() -> Self {
        Self {
            objects_per_level: 3,
            weight: 1.0,
            middle_from: 0.125,
            large_from: 0.25,
            partial_filter_from: 0.75,
            partial_iou_threshold: 0.3,
            only_objects_with_gaussians: false,
            fade_from_step: None,
        }
    }
}

impl ObjectLossConfig {
    /// Checks ranges; names the offending field.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let fraction = |name, value: f32| {
            if (0.0..=1.0).contains(&value) {
                Ok(())
            } else {
                Err((name, format!("{value} must be within 0..=1")))
            }
        };
        fraction("object_loss.middle_from", self.middle_from)?;
        fraction("object_loss.large_from", self.large_from)?;
        fraction("object_loss.partial_filter_from", self.partial_filter_from)?;
        fraction(
            "object_loss.partial_iou_threshold",
            self.partial_iou_threshold,
        )?;
        if self.middle_from > self.large_from {
            return Err((
                "object_loss.middle_from",
                "must not be after large_from (levels join small to large)".to_string(),
            ));
        }
        if !(self.weight.is_finite() && self.weight >= 0.0) {
            return Err(("object_loss.weight", "must be a finite number >= 0".into()));
        }
        if self.objects_per_level > MAX_OBJECTS_PER_LEVEL {
            return Err((
                "object_loss.objects_per_level",
                format!("at most {MAX_OBJECTS_PER_LEVEL}"),
            ));
        }
        Ok(())
    }

    /// Levels whose objects are trained at `step` of `total_steps`.
    pub fn active_levels(&self, step: u32, total_steps: u32) -> Vec<Level> {
        let progress = step as f32 / total_steps.max(1) as f32;
        let mut levels = vec![Level::Small];
        if progress >= self.middle_from {
            levels.push(Level::Middle);
        }
        if progress >= self.large_from {
            levels.push(Level::Large);
        }
        levels
    }

    /// Each object render's loss weight at `step` (`weight`, fading from `fade_from_step`).
    pub fn weight_at(&self, step: u32) -> f32 {
        match self.fade_from_step {
            Some(from) if step > from => {
                let remaining = 2.0 - step as f32 / from.max(1) as f32;
                self.weight * remaining.clamp(0.0, 1.0)
            }
            _ => self.weight,
        }
    }

    /// The first step at which partial masks are filtered.
    pub fn partial_filter_step(&self, total_steps: u32) -> u32 {
        (self.partial_filter_from * total_steps as f32).round() as u32
    }
}

/// Bounds the loss slots a step needs (1 + 3 levels x m).
pub const MAX_OBJECTS_PER_LEVEL: u32 = 16;

/// One training view's object masks, as the trainer is given them (borrowed: they are copied
/// once, into the GPU's buffers).
pub struct ViewIdMaps<'a> {
    /// Pixels per row of every level's map.
    pub width: u32,
    /// Per level: `width * height` u32 object ids (0 = none), row-major.
    pub ids: [&'a [u32]; 3],
}

/// One training view's object masks on the GPU.
pub struct ViewObjectMasks {
    /// Per level: `width * height` u32 object ids (0 = none), the loss kernel's mask layout.
    pub ids: [wgpu::Buffer; 3],
    /// Per level: which object each 8x8 square holds (`loss::object_cell_map`), so the object
    /// loss finds its mask's squares without reading the ids.
    pub cell_maps: [wgpu::Buffer; 3],
    /// Pixels per row of the maps.
    pub width: u32,
    /// Per level: the objects present, sorted.
    pub present: [Vec<u32>; 3],
    /// Per level: each present object's mask pixels (in `present`'s order).
    pub mask_pixels: [Vec<u32>; 3],
    /// Per level: the pixels of the id map (the trainer checks them against the view's).
    pub pixel_counts: [usize; 3],
}

/// The object masks of every training view, in the trainer's training-view order.
pub struct ObjectTargets {
    pub views: Vec<ViewObjectMasks>,
}

impl ObjectTargets {
    /// Uploads per-view id maps. `masks[v]` must have the training view's size.
    /// What each view's maps say (objects, their pixels, the squares' objects) is worked out on
    /// every core; the uploads follow in view order.
    pub fn upload(ctx: &GpuContext, masks: &[ViewIdMaps]) -> Self {
        let buffer = |label, contents: &[u32]| {
            wgpu::util::DeviceExt::create_buffer_init(
                &ctx.device,
                &wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: bytemuck::cast_slice(contents),
                    usage: wgpu::BufferUsages::STORAGE,
                },
            )
        };
        let summaries: Vec<_> = masks
            .par_iter()
            .map(|view| {
                let [small, middle, large] = view.ids.map(present_objects);
                let cell_maps = view.ids.map(|ids| object_cell_map(ids, view.width));
                (
                    [small.0, middle.0, large.0],
                    [small.1, middle.1, large.1],
                    cell_maps,
                )
            })
            .collect();
        let views = masks
            .iter()
            .zip(summaries)
            .map(
                |(view, (present, mask_pixels, cell_maps))| ViewObjectMasks {
                    ids: view.ids.map(|ids| buffer("object mask", ids)),
                    cell_maps: cell_maps.map(|map| buffer("object cell map", &map)),
                    width: view.width,
                    present,
                    mask_pixels,
                    pixel_counts: view.ids.map(<[u32]>::len),
                },
            )
            .collect();
        Self { views }
    }
}

/// The objects of an id map, sorted, and each one's pixels.
fn present_objects(ids: &[u32]) -> (Vec<u32>, Vec<u32>) {
    id_pixel_counts(ids)
        .into_iter()
        .map(|(id, pixels)| (id, pixels as u32))
        .unzip()
}

/// An (object, view) pair left out as a partial mask.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct SkippedPair {
    /// Index into the trainer's training views.
    pub train_view: usize,
    pub level: Level,
    pub object_id: u32,
}

/// Picks up to `count` distinct objects of `present` that are not skipped for this view.
pub fn sample_objects<R: Rng>(
    present: &[u32],
    count: u32,
    is_skipped: impl Fn(u32) -> bool,
    rng: &mut R,
) -> Vec<u32> {
    let eligible: Vec<u32> = present
        .iter()
        .copied()
        .filter(|&id| !is_skipped(id))
        .collect();
    eligible
        .choose_multiple(rng, count as usize)
        .copied()
        .collect()
}

/// Per level, the objects that Gaussians carry, from the model's ids (3 per Gaussian: small,
/// middle, large; `OBJECT_NONE` for none).
pub fn objects_owned(ids: &[u32]) -> [BTreeSet<u32>; 3] {
    let mut owned: [BTreeSet<u32>; 3] = Default::default();
    for gaussian in ids.chunks_exact(3) {
        for (level, &id) in gaussian.iter().enumerate() {
            if id != OBJECT_NONE {
                owned[level].insert(id);
            }
        }
    }
    owned
}

/// IoU of `alpha > 0.5` with `ids == object_id`: the CPU reference of the partial-mask filter's GPU
/// counts (`mask_iou`).
pub fn rendered_mask_iou(alpha: impl Iterator<Item = f32>, ids: &[u32], object_id: u32) -> f32 {
    let (mut intersection, mut union) = (0u64, 0u64);
    for (a, &id) in alpha.zip(ids) {
        let rendered = a > 0.5;
        let masked = id == object_id;
        intersection += u64::from(rendered && masked);
        union += u64::from(rendered || masked);
    }
    if union == 0 {
        0.0
    } else {
        intersection as f32 / union as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn objects_owned_are_the_ids_gaussians_carry_per_level() {
        let ids = [
            4,
            OBJECT_NONE,
            9, //
            4,
            2,
            9, //
            7,
            2,
            OBJECT_NONE,
        ];
        let owned = objects_owned(&ids);
        assert_eq!(owned[0].iter().copied().collect::<Vec<_>>(), [4, 7]);
        assert_eq!(owned[1].iter().copied().collect::<Vec<_>>(), [2]);
        assert_eq!(owned[2].iter().copied().collect::<Vec<_>>(), [9]);
    }

    #[test]
    fn levels_join_small_to_large() {
        let config = ObjectLossConfig::default();
        assert_eq!(config.active_levels(0, 800), vec![Level::Small]);
        assert_eq!(
            config.active_levels(100, 800),
            vec![Level::Small, Level::Middle]
        );
        assert_eq!(config.active_levels(200, 800), Level::ALL.to_vec());
        assert_eq!(config.partial_filter_step(800), 600);
        let at_the_end = ObjectLossConfig {
            partial_filter_from: 1.0,
            ..config
        };
        assert_eq!(at_the_end.partial_filter_step(800), 800);
    }

    #[test]
    fn sampling_skips_and_never_repeats() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for _ in 0..50 {
            let picked = sample_objects(&[1, 2, 3, 4], 3, |id| id == 2, &mut rng);
            assert_eq!(picked.len(), 3);
            assert!(!picked.contains(&2));
            let mut unique = picked.clone();
            unique.sort_unstable();
            unique.dedup();
            assert_eq!(unique.len(), 3);
        }
        assert!(sample_objects(&[], 3, |_| false, &mut rng).is_empty());
    }

    #[test]
    fn object_pixels_are_counted_in_present_order() {
        let ids = [0, 7, 3, 7, 0, 7];
        let (present, pixels) = present_objects(&ids);
        assert_eq!(present, vec![3, 7]);
        assert_eq!(pixels, vec![1, 3]);
    }

    #[test]
    fn mask_iou_counts_alpha_over_half() {
        let alpha = [0.9, 0.6, 0.4, 0.0];
        let ids = [5, 0, 5, 5];
        // rendered: {0, 1}; mask: {0, 2, 3}; intersection 1, union 4.
        assert!((rendered_mask_iou(alpha.into_iter(), &ids, 5) - 0.25).abs() < 1e-6);
    }

    #[test]
    fn invalid_configs_name_their_field() {
        let config = ObjectLossConfig {
            middle_from: 0.5,
            large_from: 0.2,
            ..Default::default()
        };
        assert_eq!(config.validate().unwrap_err().0, "object_loss.middle_from");
    }

    #[test]
    fn the_weight_fades_to_zero_over_as_many_steps_again() {
        let kept = ObjectLossConfig {
            weight: 2.0,
            ..Default::default()
        };
        assert_eq!(kept.weight_at(1_000_000), 2.0);
        let fading = ObjectLossConfig {
            fade_from_step: Some(3000),
            ..kept
        };
        assert_eq!(fading.weight_at(0), 2.0);
        assert_eq!(fading.weight_at(3000), 2.0);
        assert!((fading.weight_at(4500) - 1.0).abs() < 1e-6);
        assert_eq!(fading.weight_at(6000), 0.0);
        assert_eq!(fading.weight_at(15_000), 0.0);
        let from_zero = ObjectLossConfig {
            fade_from_step: Some(0),
            ..kept
        };
        assert_eq!(from_zero.weight_at(0), 2.0);
        assert_eq!(from_zero.weight_at(2), 0.0);
    }
}
