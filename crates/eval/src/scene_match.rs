//! Does the ground truth belong to the scene? A label scored against the wrong scene (another
//! capture's frame names, another image shape) gives a number that means nothing, so
//! `segsplat eval` refuses it unless forced (issue 41, item 5).

use crate::ground_truth::{GroundTruthFrame, stem};

/// What the scene says of one frame: its name and image size.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneFrame {
    pub name: String,
    pub width: u32,
    pub height: u32,
}

/// Relative difference of aspect ratios past which a label is another image: downscaled
/// uploads keep the aspect to well under this, a crop or another camera does not.
const ASPECT_TOLERANCE: f64 = 0.02;

/// Every way `frames` do not match `scene`, one line each (empty: they match). A frame's name
/// must be the scene frame's at its index (compared without folders and extension), and its
/// masks' aspect the scene frame's.
pub fn scene_mismatches(frames: &[GroundTruthFrame], scene: &[SceneFrame]) -> Vec<String> {
    let mut problems = Vec::new();
    for frame in frames {
        let Some(scene_frame) = scene.get(frame.frame_index) else {
            problems.push(format!(
                "label frame {:?} is index {}, past the scene's {} frames",
                frame.frame_name,
                frame.frame_index,
                scene.len()
            ));
            continue;
        };
        if stem(&frame.frame_name) != stem(&scene_frame.name) {
            problems.push(format!(
                "label frame {:?} is index {}, where the scene has {:?}",
                frame.frame_name, frame.frame_index, scene_frame.name
            ));
        }
        if let Some(query) = frame.queries.first() {
            let (width, height) = (query.mask.width(), query.mask.height());
            let label_aspect = f64::from(width) / f64::from(height.max(1));
            let scene_aspect = f64::from(scene_frame.width) / f64::from(scene_frame.height.max(1));
            if (label_aspect / scene_aspect - 1.0).abs() > ASPECT_TOLERANCE {
                problems.push(format!(
                    "label frame {:?} is {width}x{height}, not the shape of the scene's {:?} ({}x{})",
                    frame.frame_name, scene_frame.name, scene_frame.width, scene_frame.height
                ));
            }
        }
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ground_truth::GroundTruthQuery;
    use segsplat_vision::segment::BitMask;

    fn frame(name: &str, index: usize, width: u32, height: u32) -> GroundTruthFrame {
        let mut mask = BitMask::new(width, height);
        mask.set(0, 0, true);
        GroundTruthFrame {
            frame_name: name.to_string(),
            frame_index: index,
            queries: vec![GroundTruthQuery {
                text: "mug".to_string(),
                mask,
            }],
        }
    }

    fn scene() -> Vec<SceneFrame> {
        (0..3)
            .map(|index| SceneFrame {
                name: format!("images/frame_{:05}.jpg", index + 1),
                width: 1000,
                height: 750,
            })
            .collect()
    }

    #[test]
    fn labels_of_the_scene_match_at_any_resolution() {
        let frames = [
            frame("frame_00001.jpg", 0, 1000, 750),
            frame("frame_00003", 2, 400, 300),
        ];
        assert!(scene_mismatches(&frames, &scene()).is_empty());
    }

    #[test]
    fn another_name_another_shape_or_a_missing_frame_is_named() {
        let problems = scene_mismatches(
            &[
                frame("00042.jpg", 0, 1000, 750),
                frame("frame_00002.jpg", 1, 1000, 1000),
                frame("frame_00009.jpg", 8, 1000, 750),
            ],
            &scene(),
        );
        assert_eq!(problems.len(), 3, "{problems:?}");
        assert!(problems[0].contains("\"00042.jpg\"") && problems[0].contains("frame_00001"));
        assert!(problems[1].contains("1000x1000"));
        assert!(problems[2].contains("past the scene's 3 frames"));
    }
}
