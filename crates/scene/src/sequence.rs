//! The order in which a dynamic capture's frames form a video, for stages that carry state from
//! one frame to the next (mask propagation re-prompts each frame with the previous frame's
//! masks, so consecutive frames must look alike).
//!
//! - One moving camera (D-NeRF, Nerfies/HyperNeRF, a phone video): frames by capture time.
//! - A rig of fixed cameras filming the same instants (Neu3D): sorting by time alone would jump
//!   between cameras at every step. Each camera's video is walked instead, camera after camera
//!   by name (rigs name their cameras along the rig), every other one backwards ("serpentine"),
//!   so that the only cuts are from one camera to the next at the same instant, where nothing in
//!   the scene has moved.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use super::Scene;

/// A capture's frames in video order, and how many camera sequences that order walks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VideoOrder {
    /// Indices into `scene.frames`.
    pub frames: Vec<usize>,
    /// Camera sequences walked (1 for a single moving camera).
    pub sequences: usize,
}

/// `frames` (indices into `scene.frames`) in video order; see the module docs. Frames without a
/// time count as time 0; ties keep their listing order.
pub fn video_order(scene: &Scene, frames: &[usize]) -> VideoOrder {
    let time = |index: usize| scene.frames[index].time.unwrap_or(0.0);
    let cameras: Vec<String> = frames
        .iter()
        .map(|&index| camera_of(&scene.frames[index].name))
        .collect();
    let rig = filmed_by_a_rig(scene, frames, &cameras);
    let mut sequences: BTreeMap<String, Vec<usize>> = BTreeMap::new();
    for (&index, camera) in frames.iter().zip(cameras) {
        let sequence = if rig { camera } else { String::new() };
        sequences.entry(sequence).or_default().push(index);
    }
    let count = sequences.len();
    let mut ordered = Vec::with_capacity(frames.len());
    for (position, mut sequence) in sequences.into_values().enumerate() {
        sequence.sort_by(|&a, &b| time(a).total_cmp(&time(b)).then(a.cmp(&b)));
        if position % 2 == 1 {
            sequence.reverse();
        }
        ordered.extend(sequence);
    }
    VideoOrder {
        frames: ordered,
        sequences: count,
    }
}

/// A rig films one instant from several cameras: some time is shared by frames of different
/// cameras. (Two frames of one folder at one time, such as HyperNeRF's paired phones, are one
/// sequence: they alternate with a small baseline. Frames without times are a photo collection
/// in listing order, never a rig.)
/// `cameras[i]` is the camera of `frames[i]`.
fn filmed_by_a_rig(scene: &Scene, frames: &[usize], cameras: &[String]) -> bool {
    let mut camera_at: HashMap<u32, &str> = HashMap::new();
    for (&index, camera) in frames.iter().zip(cameras) {
        let Some(time) = scene.frames[index].time else {
            return false;
        };
        match camera_at.get(&time.to_bits()) {
            Some(other) if *other != camera => return true,
            Some(_) => {}
            None => {
                camera_at.insert(time.to_bits(), camera);
            }
        }
    }
    false
}

/// The camera a frame comes from: the folder part of its name (`cam03/0001.png` -> `cam03`).
fn camera_of(name: &str) -> String {
    Path::new(name)
        .parent()
        .map(|parent| parent.to_string_lossy().into_owned())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Frame, Intrinsics, SceneFormat};

    fn scene(frames: &[(&str, f32)]) -> Scene {
        Scene {
            root: "/".into(),
            format: SceneFormat::Neu3d,
            frames: frames
                .iter()
                .map(|&(name, time)| Frame {
                    name: name.to_string(),
                    image_path: name.into(),
                    intrinsics: Intrinsics {
                        width: 1,
                        height: 1,
                        fx: 1.0,
                        fy: 1.0,
                        cx: 0.5,
                        cy: 0.5,
                        model: "PINHOLE".into(),
                        distortion: Vec::new(),
                    },
                    world_from_camera: glam::Mat4::IDENTITY,
                    time: Some(time),
                    source_id: None,
                    split: None,
                })
                .collect(),
            points: None,
            masks: None,
            background: [1.0; 3],
        }
    }

    #[test]
    fn one_camera_is_walked_by_time_whatever_the_listing() {
        // D-NeRF lists training frames before test frames; HyperNeRF ids need not follow time.
        let scene = scene(&[
            ("train/r_0.png", 0.0),
            ("train/r_2.png", 0.5),
            ("test/r_1.png", 0.25),
            ("train/r_4.png", 1.0),
            ("test/r_3.png", 0.75),
        ]);
        let all: Vec<usize> = (0..5).collect();
        let order = video_order(&scene, &all);
        assert_eq!(order.frames, vec![0, 2, 1, 4, 3]);
        assert_eq!(order.sequences, 1);
    }

    #[test]
    fn a_rig_is_walked_camera_by_camera_in_a_serpentine() {
        let mut listed = Vec::new();
        for camera in ["cam01", "cam02", "cam03"] {
            for (frame, time) in [(0, 0.0), (1, 0.5), (2, 1.0)] {
                listed.push((format!("{camera}/{frame:04}.png"), time));
            }
        }
        let named: Vec<(&str, f32)> = listed.iter().map(|(n, t)| (n.as_str(), *t)).collect();
        let scene = scene(&named);
        // Training views in a shuffled order still come out as three videos.
        let frames = vec![4, 0, 8, 2, 6, 1, 5, 3, 7];
        let order = video_order(&scene, &frames);
        let names: Vec<&str> = order
            .frames
            .iter()
            .map(|&i| scene.frames[i].name.as_str())
            .collect();
        assert_eq!(
            names,
            [
                "cam01/0000.png",
                "cam01/0001.png",
                "cam01/0002.png",
                "cam02/0002.png",
                "cam02/0001.png",
                "cam02/0000.png",
                "cam03/0000.png",
                "cam03/0001.png",
                "cam03/0002.png",
            ],
            "cameras by name, every other one backwards"
        );
        assert_eq!(order.sequences, 3);
    }

    #[test]
    fn frames_without_times_keep_their_listing_order() {
        let mut scene = scene(&[("a/1.png", 0.0), ("b/1.png", 0.0), ("a/2.png", 0.0)]);
        for frame in &mut scene.frames {
            frame.time = None;
        }
        let order = video_order(&scene, &[2, 0, 1]);
        assert_eq!(order.frames, vec![0, 1, 2]);
        assert_eq!(order.sequences, 1);
    }

    #[test]
    fn paired_phones_in_one_folder_stay_one_sequence() {
        let scene = scene(&[
            ("left_000.png", 0.0),
            ("right_000.png", 0.0),
            ("left_001.png", 1.0),
            ("right_001.png", 1.0),
        ]);
        let order = video_order(&scene, &[3, 2, 1, 0]);
        assert_eq!(order.frames, vec![0, 1, 2, 3]);
        assert_eq!(order.sequences, 1);
    }
}
