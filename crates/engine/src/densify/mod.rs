//! Adaptive density control (3DGS): clone small Gaussians and split large ones where the
//! accumulated screen-space gradient is high, prune transparent or oversized ones, with a hook
//! ([`PruneGuard`]) that lets the caller veto pruning (Segment then Splat's per-object floor).
//!
//! Two implementations of one rule. [`plan_densification`] is the reference: it decides on the
//! CPU and returns the new order as origins, which [`DensifyPlan::gather`] applies uniformly to
//! parameters and optimiser moments alike. [`gpu::GpuDensifier`] is what training runs: the same
//! decisions in kernels (classify, rank, scan, scatter), so only counts come back to the host.
//! Both compare the same stored values against the same thresholds ([`DensifyThresholds`]) and
//! draw split offsets from the same counter-based generator ([`split_draw`]), so they agree
//! Gaussian for Gaussian (tests/gpu_densify.rs). Children inherit all three object ids.

pub mod gpu;
mod guard;
pub mod split_draw;

pub use guard::{GuardInputs, ObjectFloor, PruneGuard};

use glam::Vec3;
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::model::GaussianModel;

/// Thresholds (3DGS defaults, with the absolute-gradient threshold of the released
/// Segment-then-Splat code).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DensifyConfig {
    /// Mean accumulated |d loss / d mean2d| (NDC units) above which a Gaussian is densified.
    pub gradient_threshold: f32,
    /// Gaussians whose largest scale is at most this fraction of the scene extent are cloned,
    /// larger ones split.
    pub percent_dense: f32,
    /// Gaussians with opacity below this are pruned.
    pub min_opacity: f32,
    /// Prune Gaussians whose projected radius exceeded this fraction of the image's longer side
    /// (gsplat's `prune_scale2d`; None: no screen test).
    pub max_screen_radius_fraction: Option<f32>,
    /// Prune Gaussians whose largest scale exceeds this fraction of the extent (None: no test).
    pub max_world_scale_fraction: Option<f32>,
    /// Children per split (3DGS: 2); their scale is the parent's / (0.8 * children).
    pub split_children: u32,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        Self {
            gradient_threshold: 0.0007,
            percent_dense: 0.01,
            min_opacity: 0.005,
            max_screen_radius_fraction: None,
            max_world_scale_fraction: None,
            split_children: 2,
        }
    }
}

/// What the GPU accumulated since the last densification.
#[derive(Debug, Clone, Default)]
pub struct DensifyStats {
    /// Sum over renders of the absolute 2D mean gradient norm (NDC units).
    pub gradient_sums: Vec<f32>,
    /// Renders in which the Gaussian was visible.
    pub visible_counts: Vec<u32>,
    /// Largest projected radius as a fraction of the image's longer side.
    pub max_radii: Vec<f32>,
}

/// One densification's thresholds in the form both implementations compare against: scale
/// limits as logs, the opacity floor as a logit, computed once on the CPU. Comparing stored
/// log-scales and logits directly (instead of exponentials on each side) keeps the CPU plan and
/// the GPU kernels from disagreeing at a boundary over an ulp of `exp`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DensifyThresholds {
    /// Densify when gradient_sum >= gradient * visible_count.
    pub gradient: f32,
    /// Clone when the largest log-scale is at most this, split above it.
    pub log_dense_limit: f32,
    /// Prune when the opacity logit is below this.
    pub min_opacity_logit: f32,
    /// Prune when the largest projected radius (fraction of the longer side) exceeds this.
    pub screen_radius: f32,
    /// Prune when the largest log-scale exceeds this.
    pub log_world_scale: f32,
}

impl DensifyThresholds {
    pub fn new(config: &DensifyConfig, scene_extent: f32) -> Self {
        let opacity = config.min_opacity;
        Self {
            gradient: config.gradient_threshold,
            log_dense_limit: (config.percent_dense * scene_extent).ln(),
            min_opacity_logit: (opacity / (1.0 - opacity)).ln(),
            // f32::MAX rather than infinity: shader compilers may assume no infinities.
            screen_radius: config.max_screen_radius_fraction.unwrap_or(f32::MAX),
            log_world_scale: config
                .max_world_scale_fraction
                .map_or(f32::MAX, |fraction| (fraction * scene_extent).ln()),
        }
    }

    /// Whether Gaussian `i` grows, and whether it is a pruning candidate.
    fn classify(&self, model: &GaussianModel, stats: &DensifyStats, i: usize) -> (Growth, bool) {
        let visible = stats.visible_counts.get(i).copied().unwrap_or(0);
        let gradient_sum = stats.gradient_sums.get(i).copied().unwrap_or(0.0);
        let max_log_scale = model.log_scales[i].iter().copied().fold(f32::MIN, f32::max);
        let growth = if gradient_sum >= self.gradient * visible as f32 {
            if max_log_scale <= self.log_dense_limit {
                Growth::Clone
            } else {
                Growth::Split
            }
        } else {
            Growth::None
        };
        let max_radius = stats.max_radii.get(i).copied().unwrap_or(0.0);
        let prune = model.opacity_logits[i] < self.min_opacity_logit
            || max_radius > self.screen_radius
            || max_log_scale > self.log_world_scale;
        // A pruning candidate does not grow: its copies would be pruned with it (they inherit
        // its opacity and size), and under a growth bound it would take room from one that
        // stays. Spared by a guard, it stays as it is.
        if prune {
            (Growth::None, true)
        } else {
            (growth, false)
        }
    }
}

/// Where each output Gaussian comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Origin {
    /// The Gaussian itself, with its optimiser state.
    Keep(u32),
    /// A copy of a small Gaussian (fresh optimiser state).
    Clone(u32),
    /// A child of a large Gaussian, displaced by `offset` in world space, scale shrunk.
    Split { parent: u32, offset: [f32; 3] },
}

impl Origin {
    fn source(&self) -> u32 {
        match *self {
            Origin::Keep(i) | Origin::Clone(i) => i,
            Origin::Split { parent, .. } => parent,
        }
    }
}

/// The outcome of one densification: the new Gaussian order as origins.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DensifyPlan {
    pub origins: Vec<Origin>,
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
    pub spared: usize,
}

impl DensifyPlan {
    /// Re-lays out one per-Gaussian array: kept rows copy their value, new rows get `fresh(parent
    /// value)` (e.g. the parent's parameters for clones, zeros for optimiser moments).
    pub fn gather<T: Copy>(&self, rows: &[T], fresh: impl Fn(T) -> T) -> Vec<T> {
        self.origins
            .iter()
            .map(|origin| match *origin {
                Origin::Keep(i) => rows[i as usize],
                other => fresh(rows[other.source() as usize]),
            })
            .collect()
    }

    /// Applies the plan to the model's parameters and ids.
    pub fn apply(&self, model: &GaussianModel, split_children: u32) -> GaussianModel {
        let shrink = (0.8 * split_children as f32).ln();
        let mut out = GaussianModel::default();
        for origin in &self.origins {
            let i = origin.source() as usize;
            let mut mean = model.means[i];
            let mut log_scale = model.log_scales[i];
            if let Origin::Split { offset, .. } = origin {
                mean = (Vec3::from_array(mean) + Vec3::from_array(*offset)).to_array();
                log_scale = log_scale.map(|s| s - shrink);
            }
            out.means.push(mean);
            out.log_scales.push(log_scale);
            out.rotations.push(model.rotations[i]);
            out.opacity_logits.push(model.opacity_logits[i]);
            out.sh_coefficients.push(model.sh_coefficients[i]);
            out.object_ids.push(model.object_ids[i]);
        }
        out
    }
}

/// Decides clones, splits and prunes. `scene_extent` as in [`crate::schedule::scene_extent`].
/// `max_new` bounds the Gaussians the plan adds (a clone adds one, a split `children - 1`):
/// when more candidates pass the threshold, they grow in order of their mean gradient, highest
/// first (ties by index), until the first that does not fit, so a budget fills with the
/// Gaussians the loss asks for most. `None`: no bound. Draws one seed from `rng` for the split
/// offsets ([`split_draw`]).
pub fn plan_densification<R: Rng>(
    model: &GaussianModel,
    stats: &DensifyStats,
    config: &DensifyConfig,
    scene_extent: f32,
    guard: Option<&dyn PruneGuard>,
    max_new: Option<usize>,
    rng: &mut R,
) -> DensifyPlan {
    let count = model.len();
    let children = config.split_children.max(1);
    let seed: u32 = rng.random();
    let thresholds = DensifyThresholds::new(config, scene_extent);
    let mut growth = vec![Growth::None; count];
    let mut prune = vec![false; count];
    for i in 0..count {
        (growth[i], prune[i]) = thresholds.classify(model, stats, i);
    }
    if let Some(max_new) = max_new {
        limit_growth(&mut growth, stats, children, max_new);
    }
    // Gaussians each index turns into if kept: 2 for a clone pair, `children` for a split.
    let survivors: Vec<u32> = growth.iter().map(|g| g.outputs(children)).collect();
    let candidates = prune.iter().filter(|&&p| p).count();
    if let Some(guard) = guard {
        let inputs = GuardInputs {
            object_ids: &model.object_ids,
            opacity_logits: &model.opacity_logits,
        };
        guard.spare(inputs, &mut prune, &survivors);
    }
    let mut plan = DensifyPlan {
        pruned: prune.iter().filter(|&&p| p).count(),
        ..Default::default()
    };
    plan.spared = candidates - plan.pruned;
    for i in 0..count {
        if prune[i] {
            continue;
        }
        let index = i as u32;
        match growth[i] {
            Growth::None => plan.origins.push(Origin::Keep(index)),
            Growth::Clone => {
                plan.origins.push(Origin::Keep(index));
                plan.origins.push(Origin::Clone(index));
                plan.cloned += 1;
            }
            Growth::Split => {
                for child in 0..children {
                    let offset = split_draw::split_offset(
                        seed,
                        index,
                        child,
                        model.log_scales[i],
                        model.rotations[i],
                    );
                    plan.origins.push(Origin::Split {
                        parent: index,
                        offset,
                    });
                }
                plan.split += 1;
            }
        }
    }
    plan
}

/// The mean gradient a growth bound ranks candidates by.
fn mean_gradient(stats: &DensifyStats, i: usize) -> f32 {
    let visible = stats.visible_counts.get(i).copied().unwrap_or(0).max(1);
    stats.gradient_sums.get(i).copied().unwrap_or(0.0) / visible as f32
}

/// Keeps the growth of candidates in order of mean gradient (highest first, ties by index) up
/// to the first whose additions no longer fit in `max_new`; that one and every later one stay
/// as they are. (With two children per split every candidate adds one, so this is simply the
/// `max_new` highest; the GPU pass computes it as a prefix sum over the sorted candidates.)
fn limit_growth(growth: &mut [Growth], stats: &DensifyStats, children: u32, max_new: usize) {
    let wanted: usize = growth.iter().map(|g| g.added(children) as usize).sum();
    if wanted <= max_new {
        return;
    }
    let mut candidates: Vec<usize> = (0..growth.len())
        .filter(|&i| growth[i] != Growth::None)
        .collect();
    candidates.sort_by(|&a, &b| {
        mean_gradient(stats, b)
            .total_cmp(&mean_gradient(stats, a))
            .then(a.cmp(&b))
    });
    let mut added = 0usize;
    let mut full = false;
    for i in candidates {
        let adds = growth[i].added(children) as usize;
        full = full || added + adds > max_new;
        if full {
            growth[i] = Growth::None;
        } else {
            added += adds;
        }
    }
}

/// Gaussians a densification flag word (densify_common.wgsl) becomes if kept.
fn flag_outputs(flag: u32, children: u32) -> u32 {
    Growth::from_flag(flag).outputs(children)
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Growth {
    None,
    Clone,
    Split,
}

impl Growth {
    /// The growth a GPU flag word encodes in its low two bits (densify_common.wgsl).
    fn from_flag(flag: u32) -> Self {
        match flag & 3 {
            1 => Growth::Clone,
            2 => Growth::Split,
            _ => Growth::None,
        }
    }

    /// Gaussians this one becomes if it is kept.
    fn outputs(self, children: u32) -> u32 {
        match self {
            Growth::None => 1,
            Growth::Clone => 2,
            Growth::Split => children,
        }
    }

    /// Gaussians it adds to the model.
    fn added(self, children: u32) -> u32 {
        self.outputs(children).saturating_sub(1)
    }
}

/// 3DGS's periodic opacity reset: every opacity above `max_opacity` is lowered to it, so
/// Gaussians that are not needed fade and get pruned.
pub fn reset_opacity_logits(opacity_logits: &mut [f32], max_opacity: f32) {
    let ceiling = (max_opacity / (1.0 - max_opacity)).ln();
    for logit in opacity_logits {
        *logit = logit.min(ceiling);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::init::logit;
    use crate::model::OBJECT_NONE;

    fn sigmoid(x: f32) -> f32 {
        1.0 / (1.0 + (-x).exp())
    }
    use rand::SeedableRng;

    fn model_with(scales: &[f32], opacities: &[f32], ids: &[[u32; 3]]) -> GaussianModel {
        let mut model = GaussianModel::default();
        for i in 0..scales.len() {
            model.push_simple(
                [i as f32, 0.0, 0.0],
                [scales[i].ln(); 3],
                [1.0, 0.0, 0.0, 0.0],
                logit(opacities[i]),
                [0.5; 3],
                ids[i],
            );
        }
        model
    }

    fn stats(gradients: &[f32]) -> DensifyStats {
        DensifyStats {
            gradient_sums: gradients.iter().map(|g| g * 2.0).collect(),
            visible_counts: vec![2; gradients.len()],
            max_radii: vec![0.01; gradients.len()],
        }
    }

    #[test]
    fn clones_small_splits_large_prunes_transparent_and_children_inherit_ids() {
        let ids = [[1, 10, 100], [2, 20, 200], [3, 30, 300], [4, 40, 400]];
        let model = model_with(&[0.001, 0.5, 0.001, 0.001], &[0.5, 0.5, 0.5, 0.001], &ids);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let plan = plan_densification(
            &model,
            &stats(&[0.01, 0.01, 0.0, 0.0]),
            &DensifyConfig::default(),
            1.0,
            None,
            None,
            &mut rng,
        );
        assert_eq!((plan.cloned, plan.split, plan.pruned), (1, 1, 1));
        let out = plan.apply(&model, 2);
        // 0 kept + clone, 1 split into two, 2 kept, 3 pruned.
        assert_eq!(out.len(), 5);
        assert_eq!(out.object_ids, vec![ids[0], ids[0], ids[1], ids[1], ids[2]]);
        let child_scale = out.log_scales[2][0].exp();
        assert!((child_scale - 0.5 / 1.6).abs() < 1e-5);
        assert_ne!(out.means[2], out.means[3]);
        // Optimiser moments: kept rows keep theirs, new rows start at zero.
        let moments = plan.gather(&[1.0f32, 2.0, 3.0, 4.0], |_| 0.0);
        assert_eq!(moments, vec![1.0, 0.0, 0.0, 0.0, 3.0]);
    }

    #[test]
    fn object_floor_spares_most_opaque_candidates() {
        // Object 7 (small level) has three Gaussians, all prune candidates; floor 2 keeps the two
        // most opaque. Object 8 has plenty of survivors and loses its candidate.
        let ids = [
            [7, OBJECT_NONE, OBJECT_NONE],
            [7, OBJECT_NONE, OBJECT_NONE],
            [7, OBJECT_NONE, OBJECT_NONE],
            [8, OBJECT_NONE, OBJECT_NONE],
            [8, OBJECT_NONE, OBJECT_NONE],
            [8, OBJECT_NONE, OBJECT_NONE],
        ];
        let model = model_with(&[0.01; 6], &[0.001, 0.004, 0.003, 0.9, 0.9, 0.001], &ids);
        let guard = ObjectFloor { floors: [2, 0, 0] };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let plan = plan_densification(
            &model,
            &stats(&[0.0; 6]),
            &DensifyConfig::default(),
            1.0,
            Some(&guard),
            None,
            &mut rng,
        );
        assert_eq!(plan.spared, 2);
        assert_eq!(plan.pruned, 2);
        let kept: Vec<Origin> = plan.origins.clone();
        assert_eq!(
            kept,
            vec![
                Origin::Keep(1),
                Origin::Keep(2),
                Origin::Keep(3),
                Origin::Keep(4)
            ]
        );
    }

    #[test]
    fn floor_larger_than_object_keeps_it_whole() {
        let ids = [[5, 5, 5]];
        let model = model_with(&[0.01], &[0.001], &ids);
        let guard = ObjectFloor {
            floors: [1000, 1000, 10],
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let plan = plan_densification(
            &model,
            &stats(&[0.0]),
            &DensifyConfig::default(),
            1.0,
            Some(&guard),
            None,
            &mut rng,
        );
        assert_eq!(plan.origins, vec![Origin::Keep(0)]);
    }

    #[test]
    fn a_growth_bound_keeps_the_highest_gradients() {
        // Four clone candidates and one split (adds one with two children); room for two new
        // Gaussians: the two highest gradients grow (index 3 clones, index 1 splits).
        let ids = [[OBJECT_NONE; 3]; 5];
        let model = model_with(&[0.001, 0.5, 0.001, 0.001, 0.001], &[0.5; 5], &ids);
        let gradients = [0.002, 0.009, 0.003, 0.01, 0.0];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let config = DensifyConfig::default();
        let plan = plan_densification(
            &model,
            &stats(&gradients),
            &config,
            1.0,
            None,
            Some(2),
            &mut rng,
        );
        assert_eq!((plan.cloned, plan.split), (1, 1));
        assert_eq!(plan.origins.len(), 5 + 2);
        assert!(plan.origins.contains(&Origin::Clone(3)));
        assert!(!plan.origins.contains(&Origin::Clone(0)));
        // A bound the candidates fit in changes nothing; zero room grows nothing.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let unbounded = plan_densification(
            &model,
            &stats(&gradients),
            &config,
            1.0,
            None,
            None,
            &mut rng,
        );
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let roomy = plan_densification(
            &model,
            &stats(&gradients),
            &config,
            1.0,
            None,
            Some(4),
            &mut rng,
        );
        assert_eq!(unbounded, roomy);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let full = plan_densification(
            &model,
            &stats(&gradients),
            &config,
            1.0,
            None,
            Some(0),
            &mut rng,
        );
        assert_eq!(full.origins.len(), 5);
    }

    #[test]
    fn opacity_reset_caps_opacity() {
        let mut logits = vec![logit(0.9), logit(0.001)];
        reset_opacity_logits(&mut logits, 0.01);
        assert!((sigmoid(logits[0]) - 0.01).abs() < 1e-6);
        assert!((sigmoid(logits[1]) - 0.001).abs() < 1e-6);
    }
}
