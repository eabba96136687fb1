//! The propagation loop: frame by frame, prompt, take answers, paint; every `stride` frames,
//! drop duplicates, look for new objects and re-anchor.

use image::RgbImage;

use super::duplicates::DuplicateLedger;
use super::new_objects::{Ratchet, new_object_masks};
use super::paint::{paint_level, uncovered_share};
use super::track::{Outcome, Track};
use super::{
    DuplicateDrop, FirstFrameMasks, ObjectCheck, Propagation, PropagationError, PropagationOptions,
    PropagationReport,
};
use crate::segment::{BitMask, MaskGenerator, RegionPrompt, RegionPromptSegmenter};
use segsplat_scene::Level;

/// Propagates `first` (frame 0's objects) through frames `0..frame_count`, loading frame `i` with
/// `load_frame(i)` (frame 0 is not loaded: its masks are given), prompting `segmenter` for the
/// objects and running `new_objects` on the frames where new objects are looked for.
///
/// Frames must all be the size of `first`. Ids: frame 0's are kept; each new object gets the next
/// unused id of its level (above every id frame 0 had), and an id is never reused, so ids run
/// over `1..=N` per level with gaps where tracks were dropped as duplicates.
///
/// Only one frame's image is held at a time, but the result keeps every frame's id maps (12 bytes
/// a pixel a frame), so callers pass frames at the resolution they train at.
pub fn propagate_masks<E>(
    frame_count: usize,
    mut load_frame: impl FnMut(usize) -> Result<RgbImage, E>,
    first: FirstFrameMasks,
    segmenter: &mut (impl RegionPromptSegmenter + ?Sized),
    new_objects: &mut MaskGenerator,
    options: &PropagationOptions,
) -> Result<Propagation, PropagationError>
where
    E: Into<Box<dyn std::error::Error + Send + Sync>>,
{
    options.validate()?;
    let mut state = State::new(first, options)?;
    for frame_index in 1..frame_count {
        let image = load_frame(frame_index).map_err(|source| PropagationError::LoadFrame {
            frame_index,
            source: source.into(),
        })?;
        if image.dimensions() != (state.width, state.height) {
            return Err(PropagationError::FrameSize {
                frame_index,
                found: [image.width(), image.height()],
                expected: [state.width, state.height],
            });
        }
        // No live object, nothing to encode: new objects come from the generator's own pass.
        if !state.tracks.is_empty() {
            segmenter
                .set_image(&image)
                .map_err(|source| PropagationError::Prompt {
                    frame_index,
                    source,
                })?;
            state.propagate(frame_index, segmenter)?;
        }
        let is_check = frame_index % options.stride == 0;
        if is_check {
            state.drop_duplicates(frame_index);
        }
        let mut ids = state.paint();
        if is_check {
            ids = state.check_new_objects(frame_index, &image, ids, new_objects)?;
            // Re-anchor: the next frame is prompted from the current masks alone.
            for track in &mut state.tracks {
                track.prior = None;
            }
        }
        state.frames.push(ids);
    }
    Ok(state.finish())
}

struct State<'a> {
    options: &'a PropagationOptions,
    width: u32,
    height: u32,
    tracks: Vec<Track>,
    next_id: [u32; 3],
    frames: Vec<[Vec<u32>; 3]>,
    ratchet: Ratchet,
    ledger: DuplicateLedger,
    report: PropagationReport,
}

impl<'a> State<'a> {
    fn new(
        first: FirstFrameMasks,
        options: &'a PropagationOptions,
    ) -> Result<Self, PropagationError> {
        let (width, height) = (first.width, first.height);
        if width == 0 || height == 0 {
            return Err(PropagationError::FirstFrame(format!(
                "the masks are {width}x{height}"
            )));
        }
        let mut tracks = Vec::new();
        let mut next_id = [1u32; 3];
        let mut report = PropagationReport::default();
        for (level, ids) in first.ids.iter().enumerate() {
            let masks = BitMask::all_from_instance_ids(width, height, ids)
                .map_err(|error| PropagationError::FirstFrame(error.to_string()))?;
            report.first_frame_objects[level] = masks.len();
            for (id, mask) in masks {
                next_id[level] = next_id[level].max(id.saturating_add(1));
                tracks.extend(Track::new(id, level, mask, 1.0));
            }
        }
        let ratchet = Ratchet::new(std::array::from_fn(|level| {
            uncovered_share(&first.ids[level])
        }));
        Ok(State {
            options,
            width,
            height,
            tracks,
            next_id,
            frames: vec![first.ids],
            ratchet,
            ledger: DuplicateLedger::default(),
            report,
        })
    }

    /// Prompts every live track on the current image, `prompts_per_call` at a time.
    fn propagate(
        &mut self,
        frame_index: usize,
        segmenter: &mut (impl RegionPromptSegmenter + ?Sized),
    ) -> Result<(), PropagationError> {
        let mut ended = vec![false; self.tracks.len()];
        let chunk = self.options.prompts_per_call;
        for start in (0..self.tracks.len()).step_by(chunk) {
            let batch = &mut self.tracks[start..(start + chunk).min(ended.len())];
            let prompts: Vec<RegionPrompt> = batch
                .iter_mut()
                .map(|track| track.prompt(self.options))
                .collect();
            let answers =
                segmenter
                    .predict_regions(&prompts)
                    .map_err(|source| PropagationError::Prompt {
                        frame_index,
                        source,
                    })?;
            self.report.segmenter_calls += 1;
            self.report.prompts += prompts.len() as u64;
            if answers.len() != prompts.len() {
                return Err(PropagationError::AnswerCount {
                    frame_index,
                    expected: prompts.len(),
                    found: answers.len(),
                });
            }
            for (offset, ((track, prompt), answer)) in
                batch.iter_mut().zip(prompts).zip(answers).enumerate()
            {
                let size = (answer.mask.width(), answer.mask.height());
                if size != (self.width, self.height) {
                    return Err(PropagationError::MaskSize {
                        frame_index,
                        found: [size.0, size.1],
                        expected: [self.width, self.height],
                    });
                }
                let level = track.level;
                match track.answer(prompt, answer, self.options) {
                    Outcome::Accepted => {}
                    Outcome::Lost => self.report.lost_frames[level] += 1,
                    Outcome::Ended => {
                        self.report.lost_frames[level] += 1;
                        self.report.ended[level] += 1;
                        ended[start + offset] = true;
                    }
                }
            }
        }
        let mut ended = ended.into_iter();
        self.tracks.retain(|_| !ended.next().unwrap_or(false));
        Ok(())
    }

    fn drop_duplicates(&mut self, frame_index: usize) {
        let tracks: Vec<&Track> = self.tracks.iter().collect();
        let drops = self.ledger.sample(&tracks, self.options.duplicate_iou);
        for (level, (dropped, kept, iou)) in drops {
            self.tracks
                .retain(|track| (track.level, track.id) != (level, dropped));
            self.report.duplicates.push(DuplicateDrop {
                level: Level::ALL[level],
                frame_index,
                dropped,
                kept,
                iou,
            });
        }
    }

    fn paint(&self) -> [Vec<u32>; 3] {
        std::array::from_fn(|level| paint_level(&self.tracks, level, self.width, self.height))
    }

    /// The new-object check of a check frame; returns the frame's ids with any new objects.
    fn check_new_objects(
        &mut self,
        frame_index: usize,
        image: &RgbImage,
        ids: [Vec<u32>; 3],
        generator: &mut MaskGenerator,
    ) -> Result<[Vec<u32>; 3], PropagationError> {
        let uncovered: [f64; 3] = std::array::from_fn(|level| uncovered_share(&ids[level]));
        let mut check = ObjectCheck {
            frame_index,
            uncovered,
            thresholds: self.ratchet.thresholds(),
            detection_ran: false,
            new_objects: [0; 3],
        };
        if !self.ratchet.grew(uncovered, self.options.uncovered_growth) {
            self.ratchet.settle(uncovered, false);
            self.report.checks.push(check);
            return Ok(ids);
        }
        let candidates = generator.generate(image, frame_index).map_err(|source| {
            PropagationError::NewObjects {
                frame_index,
                source,
            }
        })?;
        if let Some(wrong) =
            candidates.levels.iter().flatten().find(|scored| {
                (scored.mask.width(), scored.mask.height()) != (self.width, self.height)
            })
        {
            return Err(PropagationError::MaskSize {
                frame_index,
                found: [wrong.mask.width(), wrong.mask.height()],
                expected: [self.width, self.height],
            });
        }
        check.detection_ran = true;
        for (level, level_candidates) in candidates.levels.iter().enumerate() {
            let new = new_object_masks(
                level_candidates,
                &ids[level],
                self.options.new_object_min_area(),
                self.options.new_object_uncovered_share,
            );
            for scored in new {
                let id = self.next_id[level];
                self.next_id[level] = id.saturating_add(1);
                self.tracks.extend(Track::new(
                    id,
                    level,
                    scored.mask.clone(),
                    scored.predicted_iou,
                ));
                check.new_objects[level] += 1;
            }
        }
        let ids = self.paint();
        self.ratchet.settle(
            std::array::from_fn(|level| uncovered_share(&ids[level])),
            true,
        );
        self.report.checks.push(check);
        Ok(ids)
    }

    fn finish(mut self) -> Propagation {
        self.ledger.apply(&mut self.frames);
        for level in 0..3 {
            let mut distinct = std::collections::HashSet::new();
            for frame in &self.frames {
                let mut last = 0;
                for &id in &frame[level] {
                    if id != last {
                        distinct.insert(id);
                        last = id;
                    }
                }
            }
            distinct.remove(&0);
            self.report.objects_per_level[level] = distinct.len();
        }
        Propagation {
            width: self.width,
            height: self.height,
            frames: self.frames,
            report: self.report,
        }
    }
}
