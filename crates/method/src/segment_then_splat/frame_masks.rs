//! Each training view's masks from a generator, with progress and a stop.
//!
//! A stateless generator (classical or user masks) segments the views on every core at once: the
//! classical generator runs its three levels in parallel but a view at a time left most of a
//! 16-core machine idle (the H200 job's segment stage: 12 s for 23 views at 1000 px, which a
//! view's slowest level bounds). A model's session segments one view at a time and spreads each
//! view's work over the cores itself.
//!
//! Progress and the stop stay on the caller's thread: the views are segmented on rayon's threads
//! while the caller hears each finished view over a channel, so its callback need not be `Send`.

use std::collections::HashMap;
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;

use rayon::prelude::*;
use segsplat_scene::Scene;
use segsplat_vision::segment::{FrameMasks, MaskGenerator, StatelessGenerator};

use super::association::{AssociationError, frame_rgb8};

/// The masks of each of `frames` (by frame index), calling `view_done` with the number of views
/// segmented so far before the first view and after each one. A `Break` stops the generation
/// with [`AssociationError::Stopped`]: views already being segmented finish first (one view for
/// a model, at most one per thread otherwise). On error, the error of the earliest frame in
/// `frames` that failed.
pub fn generate_frame_masks(
    scene: &Scene,
    frames: &[usize],
    generator: &mut MaskGenerator,
    max_side: Option<u32>,
    mut view_done: impl FnMut(usize) -> ControlFlow<()>,
) -> Result<HashMap<usize, FrameMasks>, AssociationError> {
    if view_done(0).is_break() {
        return Err(AssociationError::Stopped { views_done: 0 });
    }
    match generator.stateless() {
        Some(stateless) => in_parallel(scene, frames, stateless, max_side, view_done),
        None => {
            let mut masks = HashMap::with_capacity(frames.len());
            for (done, &frame_index) in frames.iter().enumerate() {
                let image = frame_rgb8(scene, frame_index, max_side)?;
                masks.insert(frame_index, generator.generate(&image, frame_index)?);
                if view_done(done + 1).is_break() {
                    return Err(AssociationError::Stopped {
                        views_done: done + 1,
                    });
                }
            }
            Ok(masks)
        }
    }
}

fn in_parallel(
    scene: &Scene,
    frames: &[usize],
    generator: StatelessGenerator<'_>,
    max_side: Option<u32>,
    mut view_done: impl FnMut(usize) -> ControlFlow<()>,
) -> Result<HashMap<usize, FrameMasks>, AssociationError> {
    let stop = AtomicBool::new(false);
    let (finished, heard) = mpsc::channel::<()>();
    let mut views_done = 0;
    let results = std::thread::scope(|scope| {
        let segmenting = scope.spawn(|| {
            let finished = finished;
            frames
                .par_iter()
                .map(|&frame_index| {
                    if stop.load(Ordering::Relaxed) {
                        // Never read: a stop returns before the results are.
                        return Err(AssociationError::Stopped { views_done: 0 });
                    }
                    let masks = frame_rgb8(scene, frame_index, max_side)
                        .map_err(AssociationError::from)
                        .and_then(|image| Ok(generator.generate(&image, frame_index)?));
                    let _ = finished.send(());
                    masks.map(|masks| (frame_index, masks))
                })
                .collect::<Vec<_>>()
        });
        // Ends when the segmenting thread drops its sender, after the last view.
        for () in heard {
            views_done += 1;
            if view_done(views_done).is_break() {
                stop.store(true, Ordering::Relaxed);
            }
        }
        segmenting.join()
    });
    let results = match results {
        Ok(results) => results,
        Err(panic) => std::panic::resume_unwind(panic),
    };
    if stop.load(Ordering::Relaxed) {
        return Err(AssociationError::Stopped { views_done });
    }
    // In `frames`' order, so the error is the earliest failed frame's.
    results.into_iter().collect()
}
