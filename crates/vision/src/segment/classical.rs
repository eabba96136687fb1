//! The classical fallback segmenter: three levels without any learned model, so the pipeline runs
//! offline and deterministically.
//!
//! Each level is a Felzenszwalb-Huttenlocher segmentation at its own scale `k` (larger `k`, larger
//! regions), then a containment step: a region wholly enclosed by one other region (touching no
//! other region and not the image border) is absorbed into it when it is at most
//! `absorb_enclosed_ratio[level]` times the container's area. Small keeps nested parts (ratio 0),
//! middle folds small details into their surroundings, large folds in everything nested, so a
//! disc inside a rectangle is its own object at the small level and part of the rectangle at the
//! large level. Before that, thin regions (the blended bands smoothing leaves along edges) are
//! merged into the neighbour of closest colour. Regions covering `max_region_fraction` of the image or more are background: never
//! output, never containers. Regions under the minimum area are merged into neighbours by FH's
//! last step. Every mask has scores 1 (regions are certain by construction); a level's masks
//! come largest first.

use image::RgbImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::felzenszwalb::{MAX_PIXELS, PixelGraph};
use super::mask::BitMask;
use super::scored::{FrameMasks, ScoredMask};

/// Why the classical segmenter could not run.
#[derive(Debug, thiserror::Error)]
pub enum ClassicalError {
    #[error("classical segmenter config: {field} {message}")]
    InvalidConfig {
        field: &'static str,
        message: String,
    },
    #[error("cannot segment an empty {width}x{height} image")]
    EmptyImage { width: u32, height: u32 },
    #[error("cannot segment a {width}x{height} image: at most {max_pixels} pixels")]
    TooLarge {
        width: u32,
        height: u32,
        max_pixels: u64,
    },
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ClassicalConfig {
    /// Gaussian smoothing before building the graph (FH's reference value 0.8).
    pub sigma: f32,
    /// FH `k` for small, middle, large at `reference_pixels`; scaled linearly with the image's
    /// pixel count so a level means the same fraction of the image at any resolution.
    pub scale_per_level: [f32; 3],
    pub reference_pixels: u64,
    /// Regions smaller than this fraction of the image merge into a neighbour.
    pub min_region_fraction: f32,
    /// Regions at least this fraction of the image are background.
    pub max_region_fraction: f32,
    /// Per level, the largest enclosed-to-container area ratio that is absorbed.
    pub absorb_enclosed_ratio: [f32; 3],
}

impl Default for ClassicalConfig {
    fn default() -> Self {
        ClassicalConfig {
            sigma: 0.8,
            scale_per_level: [100.0, 400.0, 1600.0],
            reference_pixels: 500 * 500,
            min_region_fraction: 0.002,
            max_region_fraction: 0.5,
            absorb_enclosed_ratio: [0.0, 0.25, 1.0e6],
        }
    }
}

impl ClassicalConfig {
    pub fn validate(&self) -> Result<(), ClassicalError> {
        let invalid = |field: &'static str, message: String| {
            Err(ClassicalError::InvalidConfig { field, message })
        };
        if !(self.sigma.is_finite() && self.sigma >= 0.0) {
            return invalid(
                "sigma",
                format!("must be finite and >= 0, got {}", self.sigma),
            );
        }
        if self
            .scale_per_level
            .iter()
            .any(|scale| !(scale.is_finite() && *scale > 0.0))
        {
            return invalid(
                "scale_per_level",
                format!("must be finite and > 0, got {:?}", self.scale_per_level),
            );
        }
        if self.reference_pixels == 0 {
            return invalid("reference_pixels", "must be at least 1".to_string());
        }
        if !(0.0..1.0).contains(&self.min_region_fraction) {
            return invalid(
                "min_region_fraction",
                format!("must be within 0..1, got {}", self.min_region_fraction),
            );
        }
        if !(self.max_region_fraction > self.min_region_fraction && self.max_region_fraction <= 1.0)
        {
            return invalid(
                "max_region_fraction",
                format!(
                    "must be above min_region_fraction and at most 1, got {}",
                    self.max_region_fraction
                ),
            );
        }
        if self
            .absorb_enclosed_ratio
            .iter()
            .any(|ratio| ratio.is_nan() || *ratio < 0.0)
        {
            return invalid(
                "absorb_enclosed_ratio",
                format!("must be >= 0, got {:?}", self.absorb_enclosed_ratio),
            );
        }
        Ok(())
    }
}

/// Regions of a label image: areas, neighbours and whether each touches the image border.
struct RegionGraph {
    area: Vec<u64>,
    neighbours: Vec<std::collections::BTreeSet<u32>>,
    touches_border: Vec<bool>,
}

impl RegionGraph {
    fn new(labels: &[u32], count: usize, width: usize, height: usize) -> Self {
        let mut graph = RegionGraph {
            area: vec![0; count],
            neighbours: vec![Default::default(); count],
            touches_border: vec![false; count],
        };
        for y in 0..height {
            for x in 0..width {
                let label = labels[y * width + x];
                graph.area[label as usize] += 1;
                if x == 0 || y == 0 || x + 1 == width || y + 1 == height {
                    graph.touches_border[label as usize] = true;
                }
                // Right and down neighbours (4-connectivity) are enough to find all adjacencies.
                for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                    if nx < width && ny < height {
                        let other = labels[ny * width + nx];
                        if other != label {
                            graph.neighbours[label as usize].insert(other);
                            graph.neighbours[other as usize].insert(label);
                        }
                    }
                }
            }
        }
        graph
    }

    /// Absorbs enclosed regions into their container; returns the final region of each region
    /// (`region_from_original`). Smallest first so nested chains fold inwards out.
    fn absorb_enclosed(&mut self, ratio: f32, background_area: u64) -> Vec<u32> {
        let count = self.area.len();
        let mut region_from_original: Vec<u32> = (0..count as u32).collect();
        let mut order: Vec<usize> = (0..count).collect();
        order.sort_by_key(|&region| (self.area[region], region));
        loop {
            let mut changed = false;
            for &region in &order {
                if region_from_original[region] != region as u32
                    || self.touches_border[region]
                    || self.neighbours[region].len() != 1
                {
                    continue;
                }
                let Some(&container) = self.neighbours[region].iter().next() else {
                    continue;
                };
                let container = container as usize;
                let merged_area = self.area[container] + self.area[region];
                if self.area[container] >= background_area
                    || merged_area >= background_area
                    || self.area[region] as f64 > f64::from(ratio) * self.area[container] as f64
                {
                    continue;
                }
                self.area[container] = merged_area;
                self.area[region] = 0;
                self.neighbours[container].remove(&(region as u32));
                self.neighbours[region].clear();
                for entry in region_from_original.iter_mut() {
                    if *entry == region as u32 {
                        *entry = container as u32;
                    }
                }
                changed = true;
            }
            if !changed {
                return region_from_original;
            }
        }
    }
}

/// Merges thin regions (fewer than half of their pixels interior, i.e. with all four
/// neighbours in the region; the image border counts as inside) into the adjacent region of
/// closest mean colour, preferring regions that are not thin themselves. Smoothing turns every
/// sharp edge into a one- or two-pixel band of blended colours that FH keeps as its own strips,
/// often larger than the minimum size; they are no objects. Returns relabelled `labels`, `count`.
fn merge_thin_regions(image: &RgbImage, labels: &[u32], count: usize) -> (Vec<u32>, usize) {
    let (width, height) = (image.width() as usize, image.height() as usize);
    let mut area = vec![0u64; count];
    let mut interior = vec![0u64; count];
    let mut colour_sum = vec![[0f64; 3]; count];
    let mut neighbours = vec![std::collections::BTreeSet::<u32>::new(); count];
    for y in 0..height {
        for x in 0..width {
            let label = labels[y * width + x];
            let region = label as usize;
            area[region] += 1;
            for (sum, value) in colour_sum[region]
                .iter_mut()
                .zip(image.get_pixel(x as u32, y as u32).0)
            {
                *sum += f64::from(value);
            }
            let same = |nx: Option<usize>, ny: Option<usize>| match (nx, ny) {
                (Some(nx), Some(ny)) if nx < width && ny < height => {
                    labels[ny * width + nx] == label
                }
                _ => true,
            };
            if same(x.checked_sub(1), Some(y))
                && same(Some(x + 1), Some(y))
                && same(Some(x), y.checked_sub(1))
                && same(Some(x), Some(y + 1))
            {
                interior[region] += 1;
            }
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if nx < width && ny < height {
                    let other = labels[ny * width + nx];
                    if other != label {
                        neighbours[region].insert(other);
                        neighbours[other as usize].insert(label);
                    }
                }
            }
        }
    }
    let mean = |region: usize| colour_sum[region].map(|sum| sum / area[region].max(1) as f64);
    let is_thin: Vec<bool> = (0..count)
        .map(|region| interior[region] * 2 < area[region])
        .collect();
    let mut target_from_region: Vec<u32> = (0..count as u32).collect();
    let mut order: Vec<usize> = (0..count).filter(|&region| is_thin[region]).collect();
    order.sort_by_key(|&region| (area[region], region));
    for region in order {
        let colour = mean(region);
        let distance = |other: usize| {
            let other_colour = mean(other);
            (0..3)
                .map(|channel| (colour[channel] - other_colour[channel]).powi(2))
                .sum::<f64>()
        };
        let best = neighbours[region]
            .iter()
            .map(|&other| other as usize)
            .min_by(|&a, &b| {
                (is_thin[a], distance(a))
                    .partial_cmp(&(is_thin[b], distance(b)))
                    .unwrap_or(std::cmp::Ordering::Equal)
            });
        if let Some(best) = best {
            target_from_region[region] = best as u32;
        }
    }
    // Follow chains of thin regions to their end (a cycle of thin regions stops where it closes).
    let mut label_from_region = vec![u32::MAX; count];
    let mut next_label = 0u32;
    let final_from_region: Vec<u32> = (0..count)
        .map(|region| {
            let mut current = region;
            for _ in 0..count {
                let target = target_from_region[current] as usize;
                if target == current || !is_thin[current] {
                    break;
                }
                current = target;
            }
            current as u32
        })
        .collect();
    let relabelled = labels
        .iter()
        .map(|&label| {
            let root = final_from_region[label as usize] as usize;
            if label_from_region[root] == u32::MAX {
                label_from_region[root] = next_label;
                next_label += 1;
            }
            label_from_region[root]
        })
        .collect();
    (relabelled, next_label as usize)
}

/// One level: FH at `k` on the image's graph, containment, background and size rules, masks
/// largest first.
fn segment_level(
    image: &RgbImage,
    pixel_graph: &PixelGraph,
    config: &ClassicalConfig,
    k: f32,
    absorb_ratio: f32,
) -> Vec<ScoredMask> {
    let (width, height) = image.dimensions();
    let pixel_count = u64::from(width) * u64::from(height);
    let min_area =
        ((f64::from(config.min_region_fraction) * pixel_count as f64).ceil() as u64).max(1);
    let background_area =
        ((f64::from(config.max_region_fraction) * pixel_count as f64).ceil() as u64).max(1);
    let (labels, count) = pixel_graph.segment(k, min_area);
    let (labels, count) = merge_thin_regions(image, &labels, count);
    let mut graph = RegionGraph::new(&labels, count, width as usize, height as usize);
    let region_from_original = graph.absorb_enclosed(absorb_ratio, background_area);
    // Instance ids for the regions that become masks (id = region + 1), 0 for the rest.
    let is_object: Vec<bool> = graph
        .area
        .iter()
        .map(|&area| area >= min_area && area < background_area)
        .collect();
    let ids: Vec<u32> = labels
        .iter()
        .map(|&label| {
            let region = region_from_original[label as usize];
            if is_object[region as usize] {
                region + 1
            } else {
                0
            }
        })
        .collect();
    let Ok(masks) = BitMask::all_from_instance_ids(width, height, &ids) else {
        // `ids` has one entry per pixel by construction.
        return Vec::new();
    };
    let mut scored: Vec<ScoredMask> = masks
        .into_iter()
        .filter_map(|(_, mask)| ScoredMask::certain(mask, None))
        .collect();
    scored.sort_by_key(|scored| std::cmp::Reverse(scored.area));
    scored
}

/// The classical three-level segmentation of one image: one pixel graph, its levels segmented
/// from it in parallel.
pub fn classical_masks(
    image: &RgbImage,
    config: &ClassicalConfig,
) -> Result<FrameMasks, ClassicalError> {
    config.validate()?;
    let (width, height) = image.dimensions();
    if width == 0 || height == 0 {
        return Err(ClassicalError::EmptyImage { width, height });
    }
    let pixel_scale =
        (u64::from(width) * u64::from(height)) as f32 / config.reference_pixels as f32;
    let pixel_graph = PixelGraph::new(image, config.sigma).ok_or(ClassicalError::TooLarge {
        width,
        height,
        max_pixels: MAX_PIXELS,
    })?;
    let levels: Vec<Vec<ScoredMask>> = (0..3)
        .into_par_iter()
        .map(|level| {
            segment_level(
                image,
                &pixel_graph,
                config,
                config.scale_per_level[level] * pixel_scale,
                config.absorb_enclosed_ratio[level],
            )
        })
        .collect();
    let mut frame = FrameMasks::default();
    for (slot, level) in frame.levels.iter_mut().zip(levels) {
        *slot = level;
    }
    Ok(frame)
}
