//! Stage 1 for posed static scenes without user masks (docs/method.md, stage 1: ids "carried by
//! the 3D points that masks share"): a mask generator runs on every
//! training view, and its per-view masks get one id per object across views, per level, from
//! the sparse points they share.
//!
//! The generator runs at the training resolution (the frame downscaled to `max_side`), so its
//! masks are the id maps' own pixels: no resampling of masks, the classical generator's scales
//! follow the image size, and SAM-family models resize internally anyway. Points link masks
//! through their COLMAP tracks (the views that really saw them, at the observed pixel); points
//! without a track (scenes without tracks) are projected into every view, in front of the camera
//! and inside the image, which cannot tell occluded points apart. See [`AssociationOptions`] for
//! the rules and their thresholds.

use std::ops::ControlFlow;

use image::RgbImage;
use rayon::prelude::*;

use super::frame_masks::generate_frame_masks;
use super::global_objects::{
    drop_duplicates, objects_from_groups, paint_objects, sort_largest_first,
};
use super::id_voting::observed_positions;
use super::mask_links::{LinkRule, LocalMask, group_by_shared_points, point_hits};
use super::projected_visibility::keep_front_hits;
use super::training::point_tracks_in_views;
use super::view_masks::{ViewMaskSet, ViewMaskSetError, ViewMasks};
use segsplat_scene::{Level, Scene, SceneError, load_frame_rgb};
use segsplat_vision::segment::{FrameMasks, MaskError, MaskGenerator, SegmentError};

#[derive(Debug, thiserror::Error)]
pub enum AssociationError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Segment(#[from] SegmentError),
    #[error(transparent)]
    Masks(#[from] ViewMaskSetError),
    #[error(transparent)]
    Mask(#[from] MaskError),
    #[error("frame {frame_index} is given twice: a view's masks are made once")]
    RepeatedFrame { frame_index: usize },
    #[error("frame {frame_index}: a {level:?} mask is {found:?}, the view {expected:?}")]
    MaskSize {
        frame_index: usize,
        level: Level,
        found: [u32; 2],
        expected: [u32; 2],
    },
    #[error("associating masks across views needs sparse points; the scene has none")]
    NoSparsePoints,
    /// The caller's `view_done` asked to stop (a cancelled job, a stopping service).
    #[error("mask generation stopped on request after {views_done} view(s)")]
    Stopped { views_done: usize },
}

/// The rules of association; every default is a choice stated here.
#[derive(Debug, Clone, PartialEq)]
pub struct AssociationOptions {
    /// Two masks (in different views) are one object when the points falling in both number at
    /// least this many (3: one or two shared points are what a stray point on an outline makes)
    pub min_links: u32,
    /// ... and at least this share of the points of the mask holding fewer (0.5: two views of
    /// one object share most of the smaller view's visible points, while masks of different
    /// objects share only points near occlusion edges, measured up to 30% of a small, mostly
    /// hidden object's points on the synthetic scene).
    pub min_link_share: f32,
    /// A mask that links to nothing becomes an object only when it covers this many pixels at a
    /// 1000-pixel-wide image, scaled with the pixel count (docs/method.md's 5000 px; 46 px at 96 px
    /// wide). Smaller unlinked masks stay unlabelled.
    pub new_object_area_at_1000px: f64,
    /// A projected point (one without a track) counts for a mask only when at most this much
    /// deeper, relatively, than the mask's front (0.1: the synthetic spheres' visible surfaces
    /// sit within 10% of their front, what they hide is farther; see `projected_visibility`).
    pub projected_depth_tolerance: f32,
    /// Two objects whose masks overlap with a pooled IoU above this in the views where both
    /// appear are duplicates; the smaller is dropped (docs/method.md stage 1 step 4: 0.5).
    pub duplicate_iou: f64,
}

impl Default for AssociationOptions {
    fn default() -> Self {
        Self {
            min_links: 3,
            min_link_share: 0.5,
            new_object_area_at_1000px: 5000.0,
            projected_depth_tolerance: 0.1,
            duplicate_iou: 0.5,
        }
    }
}

/// What association did at one level.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LevelAssociation {
    /// Generator masks over all views.
    pub local_masks: usize,
    /// Objects with ids 1..=objects.
    pub objects: usize,
    /// Unions that joined two groups of masks.
    pub merges: usize,
    /// Strong links not followed because both groups held a mask of one view.
    pub refused_merges: usize,
    /// Objects dropped as duplicates of larger ones.
    pub duplicates_dropped: usize,
    /// Masks with no strong link to a mask in another view.
    pub unlinked_masks: usize,
    /// Of those, the ones under the new-object area, left unlabelled.
    pub unlinked_too_small: usize,
}

/// What association did, per level (small, middle, large).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AssociationReport {
    pub levels: [LevelAssociation; 3],
}

/// Masks for `frames` made by `generator` and associated across views: see the module docs.
pub fn generated_view_masks(
    scene: &Scene,
    frames: &[usize],
    generator: &mut MaskGenerator,
    max_side: Option<u32>,
    options: &AssociationOptions,
) -> Result<(ViewMaskSet, AssociationReport), AssociationError> {
    generated_view_masks_with_progress(scene, frames, generator, max_side, options, |_| {
        ControlFlow::Continue(())
    })
}

/// [`generated_view_masks`], calling `view_done` with the number of views segmented so far
/// before the first view and after each one (generation is most of the stage's time). A
/// `Break` from it stops the stage with [`AssociationError::Stopped`] once the views being
/// segmented are done. A stateless generator (classical, user masks) segments the views on
/// every core at once ([`super::frame_masks`]).
pub fn generated_view_masks_with_progress(
    scene: &Scene,
    frames: &[usize],
    generator: &mut MaskGenerator,
    max_side: Option<u32>,
    options: &AssociationOptions,
    view_done: impl FnMut(usize) -> ControlFlow<()>,
) -> Result<(ViewMaskSet, AssociationReport), AssociationError> {
    let mut masks = generate_frame_masks(scene, frames, generator, max_side, view_done)?;
    associate_frame_masks(scene, frames, max_side, options, |frame_index| {
        masks
            .remove(&frame_index)
            .ok_or(AssociationError::RepeatedFrame { frame_index })
    })
}

/// Associates per-view masks given by `masks_of_frame` (per frame index, the masks of each
/// level at the view's training resolution for `max_side`; ids, order and `instance_id` are
/// ignored) across `frames`.
pub fn associate_frame_masks(
    scene: &Scene,
    frames: &[usize],
    max_side: Option<u32>,
    options: &AssociationOptions,
    mut masks_of_frame: impl FnMut(usize) -> Result<FrameMasks, AssociationError>,
) -> Result<(ViewMaskSet, AssociationReport), AssociationError> {
    let points = scene
        .points
        .as_ref()
        .filter(|points| !points.positions.is_empty())
        .ok_or(AssociationError::NoSparsePoints)?;
    let geometry = ViewMaskSet {
        views: frames
            .iter()
            .map(|&frame_index| ViewMasks::without_objects(scene, frame_index, max_side))
            .collect::<Result<_, _>>()?,
    };
    let mut generated = Vec::with_capacity(frames.len());
    for view in &geometry.views {
        let masks = masks_of_frame(view.frame_index)?;
        check_sizes(&masks, view)?;
        generated.push(masks);
    }
    let tracks = point_tracks_in_views(points, &geometry);
    let positions_of_points: Vec<Vec<(usize, [f32; 2])>> = points
        .positions
        .par_iter()
        .enumerate()
        .map(|(point, &position)| {
            let track = tracks.get(point).filter(|track| !track.is_empty());
            observed_positions(position, track.map(Vec::as_slice), &geometry)
        })
        .collect();
    let view_sizes: Vec<(u32, u32)> = geometry
        .views
        .iter()
        .map(|view| (view.width, view.height))
        .collect();
    let projected: Vec<bool> = tracks.iter().map(Vec::is_empty).collect();
    let depth = |point: usize, view: usize| {
        let camera = &geometry.views[view].camera;
        camera
            .camera_from_world
            .transform_point3(points.positions[point])
            .z
    };
    let points_seen = PointsSeen {
        positions: &positions_of_points,
        projected: &projected,
        depth: &depth,
    };
    let mut report = AssociationReport::default();
    let mut ids_of_view: Vec<[Vec<u32>; 3]> = vec![Default::default(); frames.len()];
    for level in Level::ALL {
        let (ids, level_report) =
            associate_level(&generated, level, &points_seen, &view_sizes, options)?;
        for (view_ids, level_ids) in ids_of_view.iter_mut().zip(ids) {
            view_ids[level.index()] = level_ids;
        }
        report.levels[level.index()] = level_report;
    }
    let views = geometry
        .views
        .into_iter()
        .zip(ids_of_view)
        .map(|(view, ids)| view.with_level_ids(ids))
        .collect::<Result<_, _>>()?;
    Ok((ViewMaskSet { views }, report))
}

/// Where the sparse points are seen in the views.
struct PointsSeen<'a> {
    /// Per point, (view, position in mask pixels).
    positions: &'a [Vec<(usize, [f32; 2])>],
    /// Per point, whether it was projected (no track) rather than observed.
    projected: &'a [bool],
    /// Depth of a point in a view's camera.
    depth: &'a dyn Fn(usize, usize) -> f32,
}

/// One level: per view its id map, and what was done.
fn associate_level(
    generated: &[FrameMasks],
    level: Level,
    points: &PointsSeen<'_>,
    view_sizes: &[(u32, u32)],
    options: &AssociationOptions,
) -> Result<(Vec<Vec<u32>>, LevelAssociation), AssociationError> {
    let mut masks: Vec<LocalMask> = Vec::new();
    let mut masks_of_view = Vec::with_capacity(generated.len());
    for (view, frame) in generated.iter().enumerate() {
        let start = masks.len();
        masks.extend(frame.level(level).iter().map(|scored| LocalMask {
            view,
            mask: scored.mask.clone(),
            bbox: scored.bbox,
            area: scored.area,
        }));
        masks_of_view.push(start..masks.len());
    }
    let mut hits = point_hits(&masks, &masks_of_view, points.positions);
    if points.projected.iter().any(|&projected| projected) {
        let depth = |point: usize, mask: usize| (points.depth)(point, masks[mask].view);
        let tolerance = options.projected_depth_tolerance;
        keep_front_hits(&mut hits, masks.len(), points.projected, depth, tolerance);
    }
    let rule = LinkRule {
        min_links: options.min_links,
        min_share: options.min_link_share,
    };
    let view_of_mask: Vec<usize> = masks.iter().map(|local| local.view).collect();
    let grouping = group_by_shared_points(&view_of_mask, &hits, rule);
    let min_new_area = |view: usize| {
        let width = view_sizes.get(view).map_or(0, |&(width, _)| width);
        options.new_object_area_at_1000px * (f64::from(width) / 1000.0).powi(2)
    };
    let found = objects_from_groups(&masks, &grouping, min_new_area)?;
    let (mut objects, duplicates_dropped) =
        drop_duplicates(found.objects, view_sizes.len(), options.duplicate_iou)?;
    sort_largest_first(&mut objects);
    let report = LevelAssociation {
        local_masks: masks.len(),
        objects: objects.len(),
        merges: grouping.merges,
        refused_merges: grouping.refused_merges,
        duplicates_dropped,
        unlinked_masks: grouping.linked.iter().filter(|&&linked| !linked).count(),
        unlinked_too_small: found.too_small,
    };
    Ok((paint_objects(&objects, view_sizes), report))
}

fn check_sizes(masks: &FrameMasks, view: &ViewMasks) -> Result<(), AssociationError> {
    for level in Level::ALL {
        if let Some(scored) = masks
            .level(level)
            .iter()
            .find(|scored| (scored.mask.width(), scored.mask.height()) != (view.width, view.height))
        {
            return Err(AssociationError::MaskSize {
                frame_index: view.frame_index,
                level,
                found: [scored.mask.width(), scored.mask.height()],
                expected: [view.width, view.height],
            });
        }
    }
    Ok(())
}

/// The frame at the training resolution as 8-bit RGB, what generators take.
pub fn frame_rgb8(
    scene: &Scene,
    frame_index: usize,
    max_side: Option<u32>,
) -> Result<RgbImage, SceneError> {
    let image = load_frame_rgb(scene, frame_index, max_side)?;
    Ok(RgbImage::from_fn(image.width(), image.height(), |x, y| {
        image::Rgb(
            image
                .get_pixel(x, y)
                .0
                .map(|channel| (channel * 255.0).round().clamp(0.0, 255.0) as u8),
        )
    }))
}
