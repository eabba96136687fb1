//! Automatic mask generation (SAM's `SamAutomaticMaskGenerator` with Segment then Splat's
//! settings): a grid of point prompts, the decoder's three multimask outputs as the small / middle
//! / large levels, each level filtered separately.
//!
//! Per level: predicted IoU > `pred_iou_thresh`, stability >= `stability_score_thresh`, box NMS
//! (predicted IoU as the score, as SAM), small holes and islands removed, then mask NMS
//! ([`mask_nms`]). One crop (the whole image), as the released settings use.

use image::RgbImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::mask::BitMask;
use super::nms::{MaskNmsConfig, NmsCandidate, box_nms, mask_nms};
use super::prompt::{PointMasks, PointPromptSegmenter, PromptError};
use super::regions::remove_small_regions;
use super::scored::{FrameMasks, ScoredMask};

/// Why automatic masks could not be made.
#[derive(Debug, thiserror::Error)]
pub enum AutomaticError {
    #[error("automatic mask config: {field} {message}")]
    InvalidConfig {
        field: &'static str,
        message: String,
    },
    #[error("cannot segment an empty {width}x{height} image")]
    EmptyImage { width: u32, height: u32 },
    #[error(transparent)]
    Prompt(#[from] PromptError),
    #[error("prompt model answered wrongly: {0}")]
    ModelOutput(String),
}

/// Settings of automatic mask generation; defaults are the released Segment then Splat ones.
/// A job config may give any of them (`automatic` in a `segment_then_splat` config); a misspelt
/// name is refused rather than silently left at its default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutomaticConfig {
    /// Points per image side; the grid has `points_per_side^2` prompts.
    pub points_per_side: u32,
    /// Prompts sent to the model at once (bounds the memory of the logit maps).
    pub points_per_batch: usize,
    /// Keep masks whose predicted IoU is above this.
    pub pred_iou_thresh: f32,
    /// Keep masks whose stability score is at least this.
    pub stability_score_thresh: f32,
    /// Stability compares the masks at logit thresholds `0 + offset` and `0 - offset`.
    pub stability_score_offset: f32,
    /// Box NMS drops a box whose IoU with a better one is above this.
    pub box_nms_thresh: f32,
    /// Holes and islands smaller than this many pixels are filled / removed; 0 disables.
    /// In pixels of the image given, as SAM: callers working at another resolution than the
    /// released ~1000 px images can scale it by the pixel-count ratio.
    pub min_mask_region_area: u64,
    pub mask_nms: MaskNmsConfig,
}

impl Default for AutomaticConfig {
    fn default() -> Self {
        AutomaticConfig {
            points_per_side: 32,
            points_per_batch: 64,
            pred_iou_thresh: 0.7,
            stability_score_thresh: 0.85,
            stability_score_offset: 1.0,
            box_nms_thresh: 0.7,
            min_mask_region_area: 100,
            mask_nms: MaskNmsConfig::default(),
        }
    }
}

fn check_fraction(field: &'static str, value: f32) -> Result<(), AutomaticError> {
    if !(0.0..=1.0).contains(&value) {
        return Err(AutomaticError::InvalidConfig {
            field,
            message: format!("must be within 0..=1, got {value}"),
        });
    }
    Ok(())
}

impl AutomaticConfig {
    pub fn validate(&self) -> Result<(), AutomaticError> {
        if !(1..=1024).contains(&self.points_per_side) {
            return Err(AutomaticError::InvalidConfig {
                field: "points_per_side",
                message: format!("must be within 1..=1024, got {}", self.points_per_side),
            });
        }
        if self.points_per_batch == 0 {
            return Err(AutomaticError::InvalidConfig {
                field: "points_per_batch",
                message: "must be at least 1".to_string(),
            });
        }
        check_fraction("pred_iou_thresh", self.pred_iou_thresh)?;
        check_fraction("stability_score_thresh", self.stability_score_thresh)?;
        check_fraction("box_nms_thresh", self.box_nms_thresh)?;
        if !(self.stability_score_offset.is_finite() && self.stability_score_offset >= 0.0) {
            return Err(AutomaticError::InvalidConfig {
                field: "stability_score_offset",
                message: format!(
                    "must be finite and not negative, got {}",
                    self.stability_score_offset
                ),
            });
        }
        check_fraction("mask_nms.duplicate_iou", self.mask_nms.duplicate_iou)?;
        check_fraction("mask_nms.min_score", self.mask_nms.min_score)?;
        check_fraction(
            "mask_nms.inner_covered_fraction",
            self.mask_nms.inner_covered_fraction,
        )?;
        check_fraction(
            "mask_nms.outer_covered_fraction",
            self.mask_nms.outer_covered_fraction,
        )?;
        Ok(())
    }
}

/// SAM's `build_point_grid` scaled to the image: cell centres of an `n x n` grid, `[x, y]` in
/// pixels, rows top to bottom, each row left to right.
pub fn point_grid(points_per_side: u32, width: u32, height: u32) -> Vec<[f32; 2]> {
    let fraction = |index: u32| (index as f32 + 0.5) / points_per_side as f32;
    (0..points_per_side)
        .flat_map(|row| {
            (0..points_per_side).map(move |column| {
                [
                    fraction(column) * width as f32,
                    fraction(row) * height as f32,
                ]
            })
        })
        .collect()
}

/// SAM's stability score: IoU of the masks at logit thresholds `+offset` and `-offset` (the
/// first lies inside the second, so it is a ratio of areas). 0 when even the loose mask is empty.
pub fn stability_score(logits: &[f32], offset: f32) -> f32 {
    let (mut strict, mut loose) = (0u64, 0u64);
    for &logit in logits {
        strict += u64::from(logit > offset);
        loose += u64::from(logit > -offset);
    }
    if loose == 0 {
        0.0
    } else {
        (strict as f64 / loose as f64) as f32
    }
}

/// The candidate for one level of one prompt answer, if it passes the IoU and stability filters.
fn candidate_from_logits(
    logits: &[f32],
    predicted_iou: f32,
    point: [f32; 2],
    width: u32,
    height: u32,
    config: &AutomaticConfig,
) -> Result<Option<ScoredMask>, AutomaticError> {
    if predicted_iou <= config.pred_iou_thresh {
        return Ok(None);
    }
    let stability = stability_score(logits, config.stability_score_offset);
    if stability < config.stability_score_thresh {
        return Ok(None);
    }
    let mask = BitMask::from_logits(width, height, logits, 0.0)
        .map_err(|error| AutomaticError::ModelOutput(error.to_string()))?;
    let Some(bbox) = mask.bounding_box() else {
        return Ok(None);
    };
    Ok(Some(ScoredMask {
        area: mask.area(),
        mask,
        bbox,
        predicted_iou,
        stability,
        score: stability * predicted_iou,
        point: Some(point),
        instance_id: None,
    }))
}

/// Filters one batch of prompt answers into per-level candidates, masks built in parallel.
fn candidates_from_answers(
    answers: &[PointMasks],
    points: &[[f32; 2]],
    width: u32,
    height: u32,
    config: &AutomaticConfig,
) -> Result<[Vec<ScoredMask>; 3], AutomaticError> {
    if answers.len() != points.len() {
        return Err(AutomaticError::ModelOutput(format!(
            "{} answers for {} points",
            answers.len(),
            points.len()
        )));
    }
    let pixels = width as usize * height as usize;
    for (answer_index, answer) in answers.iter().enumerate() {
        if let Some(logits) = answer.logits.iter().find(|logits| logits.len() != pixels) {
            return Err(AutomaticError::ModelOutput(format!(
                "answer {answer_index} has {} logits, the {width}x{height} image needs {pixels}",
                logits.len()
            )));
        }
    }
    let jobs: Vec<(usize, usize)> = (0..answers.len())
        .filter(|answer| answers[*answer].object_present)
        .flat_map(|answer| (0..3).map(move |level| (answer, level)))
        .collect();
    let results: Vec<(usize, Option<ScoredMask>)> = jobs
        .into_par_iter()
        .map(|(answer, level)| {
            let masks = &answers[answer];
            candidate_from_logits(
                &masks.logits[level],
                masks.predicted_iou[level],
                points[answer],
                width,
                height,
                config,
            )
            .map(|candidate| (level, candidate))
        })
        .collect::<Result<_, _>>()?;
    let mut levels: [Vec<ScoredMask>; 3] = Default::default();
    for (level, candidate) in results {
        if let Some(candidate) = candidate {
            levels[level].push(candidate);
        }
    }
    Ok(levels)
}

/// One level's candidates through box NMS, small-region removal and mask NMS; best score first.
/// With `min_mask_region_area == 0` this is the NMS alone (what the benchmark measures).
pub fn postprocess_level(candidates: Vec<ScoredMask>, config: &AutomaticConfig) -> Vec<ScoredMask> {
    let boxes: Vec<_> = candidates.iter().map(|candidate| candidate.bbox).collect();
    let box_scores: Vec<f32> = candidates
        .iter()
        .map(|candidate| candidate.predicted_iou)
        .collect();
    let kept_by_box = box_nms(&boxes, &box_scores, config.box_nms_thresh);
    let mut slots: Vec<Option<ScoredMask>> = candidates.into_iter().map(Some).collect();
    let survivors: Vec<ScoredMask> = kept_by_box
        .into_iter()
        .filter_map(|index| slots[index].take())
        .collect();

    let min_area = config.min_mask_region_area;
    let cleaned: Vec<ScoredMask> = survivors
        .into_par_iter()
        .filter_map(|mut candidate| {
            if remove_small_regions(&mut candidate.mask, min_area) {
                candidate.bbox = candidate.mask.bounding_box()?;
                candidate.area = candidate.mask.area();
            }
            Some(candidate)
        })
        .collect();

    let nms_candidates: Vec<NmsCandidate<'_>> = cleaned
        .iter()
        .map(|candidate| NmsCandidate {
            mask: &candidate.mask,
            bbox: candidate.bbox,
            area: candidate.area,
            score: candidate.score,
        })
        .collect();
    let kept = mask_nms(&nms_candidates, &config.mask_nms);
    let mut slots: Vec<Option<ScoredMask>> = cleaned.into_iter().map(Some).collect();
    kept.into_iter()
        .filter_map(|index| slots[index].take())
        .collect()
}

/// Automatic masks for one image at the three levels.
pub fn generate_automatic_masks(
    segmenter: &mut dyn PointPromptSegmenter,
    image: &RgbImage,
    config: &AutomaticConfig,
) -> Result<FrameMasks, AutomaticError> {
    config.validate()?;
    let (width, height) = image.dimensions();
    if width == 0 || height == 0 {
        return Err(AutomaticError::EmptyImage { width, height });
    }
    segmenter.set_image(image)?;
    let points = point_grid(config.points_per_side, width, height);
    let mut candidates: [Vec<ScoredMask>; 3] = Default::default();
    for batch in points.chunks(config.points_per_batch) {
        let answers = segmenter.predict_points(batch)?;
        let batch_candidates = candidates_from_answers(&answers, batch, width, height, config)?;
        // The logit maps (3 x width x height floats per prompt) are dropped here; only bitsets
        // are kept across batches.
        drop(answers);
        for (level, level_candidates) in candidates.iter_mut().zip(batch_candidates) {
            level.extend(level_candidates);
        }
    }
    let [small, middle, large] = candidates;
    Ok(FrameMasks {
        levels: [
            postprocess_level(small, config),
            postprocess_level(middle, config),
            postprocess_level(large, config),
        ],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_uses_cell_centres() {
        let grid = point_grid(2, 100, 50);
        assert_eq!(
            grid,
            vec![[25.0, 12.5], [75.0, 12.5], [25.0, 37.5], [75.0, 37.5]]
        );
        assert_eq!(point_grid(32, 10, 10).len(), 1024);
    }

    #[test]
    fn stability_is_the_area_ratio_at_plus_and_minus_offset() {
        // > 1: two pixels; > -1: four pixels (-1 itself is not above -1).
        let logits = [3.0, 1.5, 0.5, -0.5, -1.0, -4.0];
        assert!((stability_score(&logits, 1.0) - 0.5).abs() < 1e-6);
        assert_eq!(stability_score(&[-5.0, -2.0], 1.0), 0.0);
        assert_eq!(stability_score(&[2.0, 5.0], 1.0), 1.0);
    }

    #[test]
    fn invalid_settings_name_their_field() {
        let mut config = AutomaticConfig {
            points_per_batch: 0,
            ..AutomaticConfig::default()
        };
        let message = config.validate().expect_err("invalid").to_string();
        assert!(message.contains("points_per_batch"), "{message}");
        config.points_per_batch = 64;
        config.mask_nms.duplicate_iou = 1.5;
        let message = config.validate().expect_err("invalid").to_string();
        assert!(message.contains("mask_nms.duplicate_iou"), "{message}");
        config.mask_nms.duplicate_iou = 0.8;
        config.stability_score_offset = f32::NAN;
        assert!(config.validate().is_err());
        assert!(AutomaticConfig::default().validate().is_ok());
    }

    #[test]
    fn filters_reject_low_iou_and_unstable_masks() {
        let config = AutomaticConfig::default();
        // Sharp logits: stable; IoU 0.7 is not above 0.7.
        let sharp = [10.0, 10.0, -10.0, -10.0];
        let rejected = candidate_from_logits(&sharp, 0.7, [0.0, 0.0], 2, 2, &config);
        assert!(matches!(rejected, Ok(None)));
        let accepted = candidate_from_logits(&sharp, 0.9, [0.0, 0.0], 2, 2, &config);
        let accepted = accepted.ok().flatten().expect("passes both filters");
        assert_eq!(accepted.area, 2);
        assert!((accepted.score - 0.9).abs() < 1e-6);
        // Soft logits: half the loose mask is below +1, stability 0.5 < 0.85.
        let soft = [2.0, 0.5, 0.5, 2.0];
        let unstable = candidate_from_logits(&soft, 0.9, [0.0, 0.0], 2, 2, &config);
        assert!(matches!(unstable, Ok(None)));
    }
}
