//! Stage 1 of the `segment_then_splat` job: the training views' masks at three levels from the
//! configured source (`auto` resolved for the scene and model directory), ids made consistent
//! across views, lost tracks merged, and the "segment" stage's report.

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::{MaskSource, SegmentThenSplatConfig};
use crate::job_kinds::stop_aware::{StopAware, StopSignal, stop_or};
use crate::job_kinds::training::{fatal, report};
use crate::jobs::{JobContext, JobFailure};
use segsplat_method::segment_then_splat::association::{
    AssociationOptions, generated_view_masks_with_progress,
};
use segsplat_method::segment_then_splat::carved_hulls::CarvedHulls;
use segsplat_method::segment_then_splat::propagated_masks::propagated_view_masks;
use segsplat_method::segment_then_splat::track_merge::{TrackMergeRule, merge_lost_tracks};
use segsplat_method::segment_then_splat::view_masks::ViewMaskSet;
use segsplat_scene::sequence::video_order;
use segsplat_scene::{Level, Scene};
use segsplat_vision::models::sam::{SamModel, SamPredictor};
use segsplat_vision::segment::propagation::PropagationOptions;
use segsplat_vision::segment::{ClassicalConfig, MaskGenerator};
/// The stage's figures as reported: views, objects per level, merges, and what the source adds.
type SegmentFigures = BTreeMap<String, f64>;

/// Stage 1's masks and figures, with the hull points the lost-track merge carved that the
/// trainer's initial model can reuse (none for the user's masks, which are not merged).
type Stage1 = (ViewMaskSet, SegmentFigures, CarvedHulls);

/// What stage 1 did, kept in `metrics.json` (the job record only holds the latest stage).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SegmentReport {
    /// The mask source used (`auto` resolved).
    pub masks: MaskSource,
    #[serde(flatten)]
    pub figures: SegmentFigures,
}

/// Stage 1: the training views' masks at three levels from the configured source, with ids
/// consistent across views. Reports the "segment" stage.
pub(super) fn view_masks_for(
    ctx: &JobContext,
    scene: &Scene,
    config: &SegmentThenSplatConfig,
    frames: &[usize],
) -> Result<(ViewMaskSet, SegmentReport, CarvedHulls), JobFailure> {
    let source = resolved_mask_source(ctx, scene, config.masks);
    let (masks, figures, carved_hulls) = masks_from(ctx, scene, config, frames, source)?;
    let report = SegmentReport {
        masks: source,
        figures,
    };
    Ok((masks, report, carved_hulls))
}

/// `auto` made concrete for this scene and model directory.
pub(super) fn resolved_mask_source(
    ctx: &JobContext,
    scene: &Scene,
    chosen: MaskSource,
) -> MaskSource {
    match chosen {
        MaskSource::Auto if scene.masks.is_some() => MaskSource::User,
        // A moving scene has no multi-view geometry to associate masks with: carry them
        // through the sequence instead.
        MaskSource::Auto if scene.is_dynamic() && sam_model(ctx).is_some() => {
            MaskSource::Propagated
        }
        MaskSource::Auto if sam_model(ctx).is_some() => MaskSource::Automatic,
        MaskSource::Auto => MaskSource::Classical,
        chosen => chosen,
    }
}

/// Stage 1 from a resolved `source`: the views' masks and the stage's figures (reported).
fn masks_from(
    ctx: &JobContext,
    scene: &Scene,
    config: &SegmentThenSplatConfig,
    frames: &[usize],
    source: MaskSource,
) -> Result<Stage1, JobFailure> {
    let max_side = config.train.max_resolution;
    let views = frames.len() as u64;
    report(ctx, "segment", 0, views, &[]);
    let mut generator = match source {
        MaskSource::User | MaskSource::Auto => {
            if scene.masks.is_none() {
                return Err(fatal(
                    "masks: \"user\" needs masks/{small,middle,large}/ instance-id PNGs in the scene",
                ));
            }
            let masks = ViewMaskSet::from_user_masks(scene, frames, max_side).map_err(fatal)?;
            let objects = Level::ALL.map(|level| masks.object_count(level));
            let figures = report_segmented(ctx, &masks, objects, &[]);
            return Ok((masks, figures, CarvedHulls::default()));
        }
        MaskSource::Automatic => {
            let model = sam_model(ctx).ok_or_else(|| {
                fatal("masks: \"automatic\" needs a SAM-family model in models.dir")
            })?;
            MaskGenerator::Automatic {
                segmenter: Box::new(StopAware::new(
                    SamPredictor::new(model),
                    StopSignal::of(ctx),
                )),
                config: config.automatic.clone(),
            }
        }
        MaskSource::Classical => MaskGenerator::Classical(ClassicalConfig::default()),
        MaskSource::Propagated => {
            let model = sam_model(ctx).ok_or_else(|| {
                fatal("masks: \"propagated\" needs a SAM-family model in models.dir")
            })?;
            return propagated_masks(ctx, scene, config, frames, model);
        }
    };
    tracing::info!(?source, views = frames.len(), "generating masks");
    // One report per view segmented (the progress reporter estimates the stage's ETA), and a
    // stop noticed between views (and between a SAM model's batches, by `StopAware`).
    let stop = StopSignal::of(ctx);
    let started = Instant::now();
    let mut last_view_done = started;
    let (masks, association) = generated_view_masks_with_progress(
        scene,
        frames,
        &mut generator,
        max_side,
        &AssociationOptions::default(),
        |done| {
            if done > 0 {
                last_view_done = Instant::now();
                report(ctx, "segment", done as u64, views, &[]);
            }
            if stop.requested() {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    )
    .map_err(|error| stop_or(ctx, error, JobFailure::Fatal))?;
    let objects = association.levels.map(|level| level.objects);
    // Where stage 1's time goes (issue 38, item 5): the views' masks, then their association
    // across views (and the merge, timed in `merge_and_report`).
    let timings = [
        ("masks_seconds", (last_view_done - started).as_secs_f64()),
        (
            "association_seconds",
            last_view_done.elapsed().as_secs_f64(),
        ),
    ];
    merge_and_report(ctx, scene, config, masks, objects, &timings)
}

/// Stage 1's common end for generated masks: the lost-track merge, then the "segment" stage's
/// report (views, objects per level, merges, and what the mask source adds).
fn merge_and_report(
    ctx: &JobContext,
    scene: &Scene,
    config: &SegmentThenSplatConfig,
    mut masks: ViewMaskSet,
    objects: [usize; 3],
    extra: &[(&str, f64)],
) -> Result<Stage1, JobFailure> {
    let started = Instant::now();
    let (merges, carved_hulls) =
        merge_lost_tracks(scene, &mut masks, &config.train, TrackMergeRule::default())
            .map_err(fatal)?;
    let mut figures = vec![
        ("lost_track_merges", merges.iter().sum::<usize>() as f64),
        ("merge_seconds", started.elapsed().as_secs_f64()),
    ];
    figures.extend_from_slice(extra);
    let figures = report_segmented(ctx, &masks, objects, &figures);
    Ok((masks, figures, carved_hulls))
}

/// Reports the finished "segment" stage: views, objects per level (found, before the lost-track
/// merge), then `extra`; returns the same figures for `metrics.json`.
fn report_segmented(
    ctx: &JobContext,
    masks: &ViewMaskSet,
    objects: [usize; 3],
    extra: &[(&str, f64)],
) -> SegmentFigures {
    let mut figures = vec![
        ("views", masks.views.len() as f64),
        ("small_objects", objects[0] as f64),
        ("middle_objects", objects[1] as f64),
        ("large_objects", objects[2] as f64),
    ];
    figures.extend_from_slice(extra);
    let views = masks.views.len() as u64;
    report(ctx, "segment", views, views, &figures);
    figures
        .into_iter()
        .map(|(name, value)| (name.to_string(), value))
        .collect()
}

/// Stage 1 by re-prompting along the training views, then the lost-track merge.
fn propagated_masks(
    ctx: &JobContext,
    scene: &Scene,
    config: &SegmentThenSplatConfig,
    frames: &[usize],
    model: SamModel,
) -> Result<Stage1, JobFailure> {
    tracing::info!(views = frames.len(), "propagating masks");
    // Masks are carried in video order (by time, camera by camera for a rig); the views go back
    // to the training order afterwards, which the object targets follow.
    let order = video_order(scene, frames);
    // Both models refuse work once a stop is asked, so the stage ends within one batch.
    let mut segmenter = StopAware::new(SamPredictor::new(model.clone()), StopSignal::of(ctx));
    let mut generator = MaskGenerator::Automatic {
        segmenter: Box::new(StopAware::new(
            SamPredictor::new(model),
            StopSignal::of(ctx),
        )),
        config: config.automatic.clone(),
    };
    let (mut masks, propagation) = propagated_view_masks(
        scene,
        &order.frames,
        &mut segmenter,
        &mut generator,
        config.train.max_resolution,
        &PropagationOptions::default(),
    )
    .map_err(|error| stop_or(ctx, error, JobFailure::Fatal))?;
    let position: std::collections::HashMap<usize, usize> =
        frames.iter().enumerate().map(|(i, &f)| (f, i)).collect();
    masks.views.sort_by_key(|view| {
        position
            .get(&view.frame_index)
            .copied()
            .unwrap_or(usize::MAX)
    });
    merge_and_report(
        ctx,
        scene,
        config,
        masks,
        propagation.objects_per_level,
        &[
            ("video_sequences", order.sequences as f64),
            ("new_object_checks", propagation.checks.len() as f64),
            (
                "duplicate_tracks_dropped",
                propagation.duplicates.len() as f64,
            ),
        ],
    )
}

/// The configured SAM-family model, when the model directory has one.
fn sam_model(ctx: &JobContext) -> Option<SamModel> {
    let store = ctx.models.store().ok()?;
    SamModel::new(store).ok()
}
