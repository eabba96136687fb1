//! Open-vocabulary segmentation scores the way LangSplat and Segment-then-Splat report them:
//! the IoU of each query's predicted mask against its ground truth, averaged over the queries of
//! a frame, then over frames. That is not the pooled mean over all (frame, query) pairs: a frame
//! with one query weighs as much as a frame with ten.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::ground_truth::{GroundTruthFrame, GroundTruthQuery};
use super::resize::at_size;
use segsplat_vision::segment::mask::BitMask;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameQueryScore {
    pub text: String,
    pub iou: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameScore {
    pub frame_name: String,
    pub frame_index: usize,
    pub queries: Vec<FrameQueryScore>,
    /// Mean IoU over `queries`; 0 when there are none (such frames are left out of reports).
    pub mean_iou: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentationReport {
    /// Frames with at least one scored query, in the order given.
    pub frames: Vec<FrameScore>,
    /// Mean over `frames` of each frame's mean IoU; 0 when no frame was scored.
    pub miou: f64,
    /// Mean IoU of each query text over the frames it was scored in.
    pub per_query: BTreeMap<String, f64>,
    pub frame_count: usize,
    /// Scored (frame, query) pairs.
    pub query_count: usize,
}

/// IoU of `predicted` against `ground_truth`, at the ground truth's resolution: a prediction of
/// another size is resized to it by nearest neighbour first. 0 when both are empty.
pub fn mask_iou(ground_truth: &BitMask, predicted: &BitMask) -> f64 {
    let predicted = at_size(predicted, ground_truth.width(), ground_truth.height());
    // The sizes are equal by construction, so the size check cannot fail.
    let intersection = ground_truth.intersection_area(&predicted).unwrap_or(0);
    let union = ground_truth.area() + predicted.area() - intersection;
    if union == 0 {
        0.0
    } else {
        intersection as f64 / union as f64
    }
}

/// Scores one frame. `predicted` gives the mask selected for a query, at any resolution, or
/// `None` when nothing was selected (IoU 0, as is an empty mask).
///
/// A query whose ground-truth mask is empty is not scored: its IoU is undefined, and the loaders
/// never produce one (an object absent from a view is not asked for in it).
pub fn score_frame(
    ground_truth: &GroundTruthFrame,
    mut predicted: impl FnMut(&GroundTruthQuery) -> Option<BitMask>,
) -> FrameScore {
    let queries: Vec<FrameQueryScore> = ground_truth
        .queries
        .iter()
        .filter(|query| !query.mask.is_empty())
        .map(|query| FrameQueryScore {
            text: query.text.clone(),
            iou: predicted(query).map_or(0.0, |mask| mask_iou(&query.mask, &mask)),
        })
        .collect();
    FrameScore {
        frame_name: ground_truth.frame_name.clone(),
        frame_index: ground_truth.frame_index,
        mean_iou: mean(queries.iter().map(|query| query.iou)),
        queries,
    }
}

/// Builds the report from scored frames; frames without a scored query are left out, since they
/// have no mean to contribute.
pub fn summarize(frames: Vec<FrameScore>) -> SegmentationReport {
    let frames: Vec<FrameScore> = frames
        .into_iter()
        .filter(|frame| !frame.queries.is_empty())
        .collect();
    let mut by_text: BTreeMap<String, (f64, usize)> = BTreeMap::new();
    for query in frames.iter().flat_map(|frame| &frame.queries) {
        let (sum, count) = by_text.entry(query.text.clone()).or_default();
        *sum += query.iou;
        *count += 1;
    }
    SegmentationReport {
        miou: mean(frames.iter().map(|frame| frame.mean_iou)),
        per_query: by_text
            .into_iter()
            .map(|(text, (sum, count))| (text, sum / count as f64))
            .collect(),
        frame_count: frames.len(),
        query_count: frames.iter().map(|frame| frame.queries.len()).sum(),
        frames,
    }
}

/// Scores every frame with `predicted(frame, query)` and summarises.
pub fn evaluate(
    ground_truth: &[GroundTruthFrame],
    mut predicted: impl FnMut(&GroundTruthFrame, &GroundTruthQuery) -> Option<BitMask>,
) -> SegmentationReport {
    summarize(
        ground_truth
            .iter()
            .map(|frame| score_frame(frame, |query| predicted(frame, query)))
            .collect(),
    )
}

/// The oracle: of `candidates` (e.g. the rendered objects of every level), the one with the best
/// IoU against `ground_truth`, with that IoU. It measures the 3D segmentation apart from the
/// language matching. Ties go to the lower index; `None` only when there is no candidate.
pub fn oracle_choice(ground_truth: &BitMask, candidates: &[BitMask]) -> Option<(usize, f64)> {
    candidates
        .iter()
        .enumerate()
        .map(|(index, candidate)| (index, mask_iou(ground_truth, candidate)))
        .fold(None, |best, (index, iou)| match best {
            Some((_, best_iou)) if best_iou >= iou => best,
            _ => Some((index, iou)),
        })
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, count) = values.fold((0.0, 0usize), |(sum, count), value| {
        (sum + value, count + 1)
    });
    if count == 0 { 0.0 } else { sum / count as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `width x height` mask with pixels `x_range` of every row in `y_range` set.
    fn block(
        width: u32,
        height: u32,
        x_range: std::ops::Range<u32>,
        y_range: std::ops::Range<u32>,
    ) -> BitMask {
        let mut mask = BitMask::new(width, height);
        for y in y_range {
            mask.set_row_span(y, x_range.clone(), true);
        }
        mask
    }

    fn query(text: &str, mask: BitMask) -> GroundTruthQuery {
        GroundTruthQuery {
            text: text.to_owned(),
            mask,
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn iou_is_taken_at_ground_truth_resolution() {
        let ground_truth = block(8, 8, 0..4, 0..8);
        // Half resolution: the left half, upsampled, is exactly the ground truth.
        assert!(close(
            mask_iou(&ground_truth, &block(4, 4, 0..2, 0..4)),
            1.0
        ));
        // Left quarter at half resolution: 16 of 32 pixels.
        assert!(close(
            mask_iou(&ground_truth, &block(4, 4, 0..1, 0..4)),
            0.5
        ));
        assert!(close(mask_iou(&ground_truth, &BitMask::new(4, 4)), 0.0));
        assert!(close(
            mask_iou(&BitMask::new(8, 8), &BitMask::new(8, 8)),
            0.0
        ));
    }

    #[test]
    fn miou_averages_per_frame_then_over_frames() {
        let frame_a = GroundTruthFrame {
            frame_name: "a.jpg".to_owned(),
            frame_index: 0,
            queries: vec![
                query("cup", block(4, 4, 0..2, 0..4)),
                query("plate", block(4, 4, 2..4, 0..4)),
            ],
        };
        let frame_b = GroundTruthFrame {
            frame_name: "b.jpg".to_owned(),
            frame_index: 3,
            queries: vec![query("cup", block(4, 4, 0..4, 0..2))],
        };
        // Frame a: cup exact (1.0), plate missed (None, 0.0). Frame b: cup exact at half size.
        let report = evaluate(&[frame_a, frame_b], |frame, query| {
            match (frame.frame_index, query.text.as_str()) {
                (0, "cup") => Some(query.mask.clone()),
                (0, _) => None,
                _ => Some(block(2, 2, 0..2, 0..1)),
            }
        });
        assert!(close(report.frames[0].mean_iou, 0.5));
        assert!(close(report.frames[1].queries[0].iou, 1.0));
        // Per frame then over frames: (0.5 + 1.0) / 2; the pooled mean is 2 / 3.
        assert!(close(report.miou, 0.75));
        let pooled = report
            .frames
            .iter()
            .flat_map(|frame| &frame.queries)
            .map(|q| q.iou)
            .sum::<f64>()
            / report.query_count as f64;
        assert!(close(pooled, 2.0 / 3.0));
        assert_eq!((report.frame_count, report.query_count), (2, 3));
        assert!(close(report.per_query["cup"], 1.0));
        assert!(close(report.per_query["plate"], 0.0));
    }

    #[test]
    fn summary_leaves_out_unscored_frames_and_round_trips_json() {
        let frames = vec![
            FrameScore {
                frame_name: "a".to_owned(),
                frame_index: 0,
                queries: vec![
                    FrameQueryScore {
                        text: "x".to_owned(),
                        iou: 1.0,
                    },
                    FrameQueryScore {
                        text: "y".to_owned(),
                        iou: 0.0,
                    },
                ],
                mean_iou: 0.5,
            },
            FrameScore {
                frame_name: "b".to_owned(),
                frame_index: 1,
                queries: vec![FrameQueryScore {
                    text: "x".to_owned(),
                    iou: 1.0,
                }],
                mean_iou: 1.0,
            },
            FrameScore {
                frame_name: "empty".to_owned(),
                frame_index: 2,
                queries: vec![],
                mean_iou: 0.0,
            },
        ];
        let report = summarize(frames);
        assert!(close(report.miou, 0.75));
        assert_eq!(report.frame_count, 2);
        assert_eq!(report.frames.len(), 2);
        let json = serde_json::to_string(&report).expect("serialises");
        let back: SegmentationReport = serde_json::from_str(&json).expect("deserialises");
        assert_eq!(back, report);
        assert!(close(summarize(vec![]).miou, 0.0));
    }

    #[test]
    fn empty_ground_truth_queries_are_not_scored() {
        let frame = GroundTruthFrame {
            frame_name: "a".to_owned(),
            frame_index: 0,
            queries: vec![
                query("ghost", BitMask::new(4, 4)),
                query("cup", block(4, 4, 0..1, 0..1)),
            ],
        };
        let score = score_frame(&frame, |query| Some(query.mask.clone()));
        assert_eq!(score.queries.len(), 1);
        assert!(close(score.mean_iou, 1.0));
    }

    #[test]
    fn oracle_picks_the_best_candidate_at_any_resolution() {
        let ground_truth = block(8, 8, 0..4, 0..4);
        let candidates = [
            block(8, 8, 4..8, 4..8), // disjoint: 0
            block(8, 8, 0..4, 0..2), // half: 0.5
            block(4, 4, 0..2, 0..2), // exact once upsampled: 1
            block(8, 8, 0..4, 0..4), // also exact, later: loses the tie
        ];
        let (index, iou) = oracle_choice(&ground_truth, &candidates).expect("candidates");
        assert_eq!(index, 2);
        assert!(close(iou, 1.0));
        assert_eq!(
            oracle_choice(&ground_truth, &candidates[..1]),
            Some((0, 0.0))
        );
        assert_eq!(oracle_choice(&ground_truth, &[]), None);
    }
}
