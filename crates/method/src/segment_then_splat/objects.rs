//! What a trained, segmented scene says about its objects: the per-object summary stored with the
//! object table (Gaussian count, centroid, bounds, mean colour), and 2D masks rendered from the
//! object's Gaussians alone (occluded parts included, as 3D segmentation implies).

use serde::{Deserialize, Serialize};

use segsplat_engine::model::{GaussianView, SH_C0};
use segsplat_engine::render::{RenderError, Renderer};
use segsplat_engine::{GaussianModel, OBJECT_NONE, ObjectFilter, RenderCamera, RenderSettings};
use segsplat_gpu::GpuContext;
use segsplat_scene::Level;

/// Gaussians at or below this opacity do not shape an object's centroid, bounds or colour: they
/// are nearly invisible and often floaters left by optimisation.
const SUMMARY_MIN_OPACITY: f32 = 0.05;
/// Bounds span this central share of the object's Gaussians per axis (robust to stray splats).
const BOUNDS_QUANTILES: (f32, f32) = (0.01, 0.99);
/// A rendered pixel belongs to the object's mask above this alpha.
pub const MASK_ALPHA_THRESHOLD: f32 = 0.5;

/// One object of one level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectSummary {
    pub level: Level,
    pub object_id: u32,
    pub gaussian_count: usize,
    /// Opacity-weighted mean of the Gaussians' centres.
    pub centroid: [f32; 3],
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
    /// Opacity-weighted mean of the view-independent (SH band 0) colour, 0..1 RGB.
    pub mean_color: [f32; 3],
}

/// Summaries of every object at every level, ordered by level then id.
pub fn summarize_objects(model: &GaussianModel) -> Vec<ObjectSummary> {
    let mut members: std::collections::BTreeMap<(Level, u32), Vec<usize>> = Default::default();
    for (index, ids) in model.object_ids.iter().enumerate() {
        for level in Level::ALL {
            let id = ids[level.index()];
            if id != OBJECT_NONE {
                members.entry((level, id)).or_default().push(index);
            }
        }
    }
    members
        .into_iter()
        .map(|((level, object_id), indices)| summarize(model, level, object_id, &indices))
        .collect()
}

fn summarize(model: &GaussianModel, level: Level, object_id: u32, all: &[usize]) -> ObjectSummary {
    let opacity = |index: usize| sigmoid(model.opacity_logits[index]);
    let visible: Vec<usize> = all
        .iter()
        .copied()
        .filter(|&index| opacity(index) > SUMMARY_MIN_OPACITY)
        .collect();
    let used = if visible.is_empty() { all } else { &visible };
    let mut weight_sum = 0.0f64;
    let mut centroid = [0.0f64; 3];
    let mut color = [0.0f64; 3];
    for &index in used {
        let weight = f64::from(opacity(index)).max(1e-6);
        weight_sum += weight;
        for axis in 0..3 {
            centroid[axis] += weight * f64::from(model.means[index][axis]);
            let dc = f64::from(model.sh_coefficients[index][0][axis]);
            color[axis] += weight * (dc * SH_C0 + 0.5).clamp(0.0, 1.0);
        }
    }
    let mut bounds_min = [0.0f32; 3];
    let mut bounds_max = [0.0f32; 3];
    for axis in 0..3 {
        let mut values: Vec<f32> = used.iter().map(|&i| model.means[i][axis]).collect();
        values.sort_unstable_by(f32::total_cmp);
        bounds_min[axis] = quantile(&values, BOUNDS_QUANTILES.0);
        bounds_max[axis] = quantile(&values, BOUNDS_QUANTILES.1);
    }
    ObjectSummary {
        level,
        object_id,
        gaussian_count: all.len(),
        centroid: centroid.map(|c| (c / weight_sum) as f32),
        bounds_min,
        bounds_max,
        mean_color: color.map(|c| (c / weight_sum) as f32),
    }
}

fn sigmoid(logit: f32) -> f32 {
    1.0 / (1.0 + (-logit).exp())
}

/// The value at quantile `q` of sorted `values` (nearest rank).
fn quantile(values: &[f32], q: f32) -> f32 {
    if values.is_empty() {
        return 0.0;
    }
    let rank = (q * (values.len() - 1) as f32).round() as usize;
    values[rank.min(values.len() - 1)]
}

/// One render read back: per pixel alpha and expected depth (camera z; +inf where nothing was
/// drawn).
#[derive(Debug, Clone)]
pub struct RenderedLayer {
    pub alpha: Vec<f32>,
    pub depth: Vec<f32>,
}

/// Pixels whose alpha is this small have no meaningful depth.
const MIN_ALPHA_FOR_DEPTH: f32 = 1e-3;
/// An object pixel counts as visible when its depth is within this fraction of the full
/// scene's depth there (soft edges blend depths slightly).
const VISIBLE_DEPTH_TOLERANCE: f32 = 0.03;

/// Bytes per pixel of the largest per-pixel buffer a render binds (the RGBA f32 image).
const IMAGE_BYTES_PER_PIXEL: u64 = 16;
/// Bands start on tile rows (16 pixels), so no band splits a tile.
const BAND_ROW_MULTIPLE: u32 = 16;
/// Pixels of one band at most, whatever the adapter allows: keeps a band's tile-intersection
/// list (which grows with the pixels covered) well inside one binding too.
const MAX_BAND_PIXELS: u64 = 4 << 20;

/// Renders `filter`'s Gaussians (the whole scene, or one object) from `camera`: in one pass
/// when the image fits the adapter's storage bindings, else in bands of rows (any mask size up
/// to the service's limit works on any adapter, e.g. lavapipe's 128 MiB bindings).
pub fn render_layer<'g>(
    ctx: &GpuContext,
    renderer: &mut Renderer,
    gaussians: impl Into<GaussianView<'g>>,
    camera: &RenderCamera,
    filter: ObjectFilter,
) -> Result<RenderedLayer, RenderError> {
    let rows = band_rows(camera.width, ctx.limits.max_storage_buffer_binding_size);
    render_layer_in_bands(ctx, renderer, gaussians, camera, filter, rows)
}

/// Rows per band for an image `width` pixels wide, given the adapter's largest binding.
pub fn band_rows(width: u32, binding_limit_bytes: u64) -> u32 {
    let row_bytes = u64::from(width.max(1)) * IMAGE_BYTES_PER_PIXEL;
    let rows = (binding_limit_bytes / row_bytes).min(MAX_BAND_PIXELS / u64::from(width.max(1)));
    let rows = u32::try_from(rows).unwrap_or(u32::MAX);
    if rows >= BAND_ROW_MULTIPLE {
        rows / BAND_ROW_MULTIPLE * BAND_ROW_MULTIPLE
    } else {
        rows.max(1)
    }
}

/// [`render_layer`] in bands of at most `band_rows` rows, stacked into one layer.
pub fn render_layer_in_bands<'g>(
    ctx: &GpuContext,
    renderer: &mut Renderer,
    gaussians: impl Into<GaussianView<'g>>,
    camera: &RenderCamera,
    filter: ObjectFilter,
    band_rows: u32,
) -> Result<RenderedLayer, RenderError> {
    let gaussians: GaussianView<'g> = gaussians.into();
    let band_rows = band_rows.max(1);
    let mut layer = RenderedLayer {
        alpha: Vec::with_capacity(camera.pixel_count()),
        depth: Vec::with_capacity(camera.pixel_count()),
    };
    let mut top = 0;
    while top < camera.height {
        let rows = band_rows.min(camera.height - top);
        let band = render_band(ctx, renderer, gaussians, &camera.band(top, rows), filter)?;
        layer.alpha.extend(band.alpha);
        layer.depth.extend(band.depth);
        top += rows;
    }
    Ok(layer)
}

fn render_band(
    ctx: &GpuContext,
    renderer: &mut Renderer,
    gaussians: GaussianView<'_>,
    camera: &RenderCamera,
    filter: ObjectFilter,
) -> Result<RenderedLayer, RenderError> {
    let settings = RenderSettings {
        filter,
        background: [0.0; 3],
        sh_degree: 0,
    };
    let output = renderer.render_checked(ctx, gaussians, camera, &settings)?;
    let pixels = camera.pixel_count();
    let image = output.read_image(ctx)?;
    let depth_sums = output.read_depth(ctx)?;
    let alpha: Vec<f32> = image.iter().take(pixels).map(|pixel| pixel[3]).collect();
    let depth = alpha
        .iter()
        .zip(&depth_sums)
        .map(|(&a, &sum)| {
            if a > MIN_ALPHA_FOR_DEPTH {
                sum / a
            } else {
                f32::INFINITY
            }
        })
        .collect();
    Ok(RenderedLayer { alpha, depth })
}

/// The object's full (amodal) mask: alpha > 0.5, occluded parts included.
pub fn full_mask(object: &RenderedLayer) -> Vec<bool> {
    object
        .alpha
        .iter()
        .map(|&a| a > MASK_ALPHA_THRESHOLD)
        .collect()
}

/// The part of the object's mask not hidden by other Gaussians: where the object is no deeper
/// than the full scene's expected depth (within a small tolerance).
pub fn visible_mask(object: &RenderedLayer, scene: &RenderedLayer) -> Vec<bool> {
    object
        .alpha
        .iter()
        .zip(&object.depth)
        .zip(&scene.depth)
        .map(|((&alpha, &object_depth), &scene_depth)| {
            alpha > MASK_ALPHA_THRESHOLD
                && object_depth <= scene_depth * (1.0 + VISIBLE_DEPTH_TOLERANCE)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summaries_weight_by_opacity_and_ignore_faint_splats() {
        let mut model = GaussianModel::default();
        let solid = 4.0; // opacity ~0.98
        let faint = -6.0; // opacity ~0.0025
        model.push_simple(
            [0.0; 3],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            solid,
            [1.0, 0.0, 0.0],
            [7, 1, OBJECT_NONE],
        );
        model.push_simple(
            [2.0, 0.0, 0.0],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            solid,
            [1.0, 0.0, 0.0],
            [7, 1, OBJECT_NONE],
        );
        model.push_simple(
            [100.0, 0.0, 0.0],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            faint,
            [0.0, 0.0, 1.0],
            [7, 2, OBJECT_NONE],
        );
        let summaries = summarize_objects(&model);
        let small = summaries
            .iter()
            .find(|s| s.level == Level::Small && s.object_id == 7)
            .expect("object 7");
        assert_eq!(small.gaussian_count, 3);
        assert!(
            (small.centroid[0] - 1.0).abs() < 1e-4,
            "{:?}",
            small.centroid
        );
        assert!(small.bounds_max[0] <= 2.0 + 1e-6);
        assert!((small.mean_color[0] - 1.0).abs() < 1e-3 && small.mean_color[2] < 1e-3);
        // The faint Gaussian alone makes middle object 2: its summary still exists.
        assert!(
            summaries
                .iter()
                .any(|s| s.level == Level::Middle && s.object_id == 2)
        );
        assert!(!summaries.iter().any(|s| s.level == Level::Large));
    }
}
