//! Per-view instance-id maps at the three levels, at the training resolution, with the camera
//! that sees them: what stages 2 and 3 read (id voting, the object loss, partial-mask checks).
//!
//! Ids are the masks' own instance ids (1, 2, ...; 0 = no object), used directly as object ids,
//! so there is no 255 limit: a 16-bit mask (or a generator) can name 65535 objects per level and
//! the engine's ids are u32.

use glam::Vec3;

use segsplat_engine::RenderCamera;
use segsplat_engine::camera::CameraError;
use segsplat_scene::id_runs::id_runs;
use segsplat_scene::{
    Frame, InstanceMask, Level, Scene, SceneError, load_instance_mask, scale_for_max_side,
    scaled_size,
};

#[derive(Debug, thiserror::Error)]
pub enum ViewMaskSetError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error("the scene has no user masks")]
    NoMasks,
    #[error("frame {frame}: {level:?} mask is {found:?}, expected {expected:?}")]
    SizeMismatch {
        frame: usize,
        level: Level,
        found: [u32; 2],
        expected: [u32; 2],
    },
    #[error("frame {frame}: {level:?} id map has {found} pixels, expected {expected}")]
    IdCount {
        frame: usize,
        level: Level,
        found: usize,
        expected: usize,
    },
}

/// One view's masks.
#[derive(Debug, Clone)]
pub struct ViewMasks {
    pub frame_index: usize,
    /// The camera at the masks' resolution.
    pub camera: RenderCamera,
    pub width: u32,
    pub height: u32,
    /// Mask pixels per full-resolution frame pixel.
    scale: f32,
    /// Row-major ids per level (small, middle, large); 0 = no object.
    ids: [Vec<u32>; 3],
}

/// The masks of a set of views.
#[derive(Debug, Clone, Default)]
pub struct ViewMaskSet {
    pub views: Vec<ViewMasks>,
}

impl ViewMasks {
    /// Builds a view from full-resolution masks (one per level), downsampled by nearest
    /// neighbour so the longest side is at most `max_side`.
    pub fn new(
        scene: &Scene,
        frame_index: usize,
        masks: [&InstanceMask; 3],
        max_side: Option<u32>,
    ) -> Result<Self, ViewMaskSetError> {
        let frame = frame_of(scene, frame_index)?;
        let (full_width, full_height) = (frame.intrinsics.width, frame.intrinsics.height);
        for (level, mask) in Level::ALL.into_iter().zip(masks) {
            if (mask.width, mask.height) != (full_width, full_height) {
                return Err(ViewMaskSetError::SizeMismatch {
                    frame: frame_index,
                    level,
                    found: [mask.width, mask.height],
                    expected: [full_width, full_height],
                });
            }
        }
        let mut view = Self::without_objects(scene, frame_index, max_side)?;
        view.ids = masks.map(|mask| downsample_nearest(mask, view.width, view.height));
        Ok(view)
    }

    /// A view whose maps hold no object yet, at the training resolution for `max_side`: the
    /// camera and size that masks made for this view must have.
    pub fn without_objects(
        scene: &Scene,
        frame_index: usize,
        max_side: Option<u32>,
    ) -> Result<Self, ViewMaskSetError> {
        let frame = frame_of(scene, frame_index)?;
        let (full_width, full_height) = (frame.intrinsics.width, frame.intrinsics.height);
        let factor = max_side.map_or(1.0, |side| {
            scale_for_max_side(full_width, full_height, side)
        });
        let (width, height) = scaled_size(full_width, full_height, factor);
        let scale = width as f32 / full_width as f32;
        let camera = RenderCamera::from_frame(frame, scale)?;
        let pixels = width as usize * height as usize;
        Ok(Self {
            frame_index,
            camera,
            width,
            height,
            scale,
            ids: [vec![0; pixels], vec![0; pixels], vec![0; pixels]],
        })
    }

    /// The same view with row-major id maps already at its resolution (e.g. from associated
    /// generated masks) in place of its own.
    pub fn with_level_ids(mut self, ids: [Vec<u32>; 3]) -> Result<Self, ViewMaskSetError> {
        let expected = self.width as usize * self.height as usize;
        for (level, level_ids) in Level::ALL.into_iter().zip(&ids) {
            if level_ids.len() != expected {
                return Err(ViewMaskSetError::IdCount {
                    frame: self.frame_index,
                    level,
                    found: level_ids.len(),
                    expected,
                });
            }
        }
        self.ids = ids;
        Ok(self)
    }

    /// Row-major ids at `level`; 0 = no object.
    pub fn ids(&self, level: Level) -> &[u32] {
        &self.ids[level.index()]
    }

    /// A copy of the ids at every level (small, middle, large).
    pub fn level_ids(&self) -> [Vec<u32>; 3] {
        self.ids.clone()
    }

    /// Rewrites, in place and run by run, every id at `level` that `replacement` maps to
    /// something.
    pub fn replace_ids(&mut self, level: Level, replacement: impl FnMut(u32) -> Option<u32>) {
        segsplat_scene::id_runs::replace_ids(&mut self.ids[level.index()], replacement);
    }

    /// Mask pixels per full-resolution frame pixel.
    pub fn frame_scale(&self) -> f32 {
        self.scale
    }

    /// Where a world point projects, in mask pixel units (pixel `(x, y)` spans `[x, x + 1)`),
    /// when it is in front of the camera and inside the image.
    pub fn position_of_point(&self, point: Vec3) -> Option<[f32; 2]> {
        let camera_point = self.camera.camera_from_world.transform_point3(point);
        if camera_point.z <= self.camera.near {
            return None;
        }
        let u = self.camera.fx * camera_point.x / camera_point.z + self.camera.cx;
        let v = self.camera.fy * camera_point.y / camera_point.z + self.camera.cy;
        self.inside(u, v).then_some([u, v])
    }

    /// A full-resolution frame pixel position (e.g. a COLMAP keypoint) in mask pixel units,
    /// when inside the image.
    pub fn position_from_frame_pixel(&self, pixel: [f32; 2]) -> Option<[f32; 2]> {
        let [u, v] = pixel.map(|c| c * self.scale);
        self.inside(u, v).then_some([u, v])
    }

    /// The mask pixel a world point projects to.
    pub fn pixel_of_point(&self, point: Vec3) -> Option<usize> {
        self.position_of_point(point)
            .map(|[u, v]| v as usize * self.width as usize + u as usize)
    }

    fn inside(&self, u: f32, v: f32) -> bool {
        u >= 0.0 && v >= 0.0 && u < self.width as f32 && v < self.height as f32
    }

    /// The id at a position, tolerant to silhouette edges: the pixel's own id when it has one,
    /// else the most common id among the 2x2 pixels whose centres surround the position. Points
    /// on an object's outline (where feature points like to sit) fall on either side of the
    /// rasterised mask edge about equally often; this keeps them with their object while a point
    /// a full pixel away from every object still reads 0.
    pub fn id_near(&self, level: Level, [u, v]: [f32; 2]) -> u32 {
        let ids = self.ids(level);
        let (width, height) = (self.width as usize, self.height as usize);
        let own = ids[v as usize * width + u as usize];
        if own != 0 {
            return own;
        }
        let (left, top) = ((u - 0.5).floor(), (v - 0.5).floor());
        let mut around = [0u32; 4];
        for (slot, (dx, dy)) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
            .into_iter()
            .enumerate()
        {
            let (x, y) = (left + dx, top + dy);
            if x >= 0.0 && y >= 0.0 && (x as usize) < width && (y as usize) < height {
                around[slot] = ids[y as usize * width + x as usize];
            }
        }
        around.sort_unstable();
        around
            .chunk_by(|a, b| a == b)
            .filter(|run| run[0] != 0)
            .max_by_key(|run| run.len())
            .map_or(0, |run| run[0])
    }

    /// Ids present at `level` (sorted, without 0).
    pub fn objects_at(&self, level: Level) -> Vec<u32> {
        let mut present: Vec<u32> = id_runs(self.ids(level))
            .map(|(id, _)| id)
            .filter(|&id| id != 0)
            .collect();
        present.sort_unstable();
        present.dedup();
        present
    }
}

impl ViewMaskSet {
    /// Distinct objects at `level` over all views.
    pub fn object_count(&self, level: Level) -> usize {
        let ids: std::collections::BTreeSet<u32> = self
            .views
            .iter()
            .flat_map(|view| view.objects_at(level))
            .collect();
        ids.len()
    }

    /// The user's masks (`masks/<level>/`) for `frame_indices`, at most `max_side` pixels on the
    /// longest side. A level the user did not give is served by the nearest given level.
    pub fn from_user_masks(
        scene: &Scene,
        frame_indices: &[usize],
        max_side: Option<u32>,
    ) -> Result<Self, ViewMaskSetError> {
        if scene.masks.is_none() {
            return Err(ViewMaskSetError::NoMasks);
        }
        let mut views = Vec::with_capacity(frame_indices.len());
        for &frame_index in frame_indices {
            let mut levels = Vec::with_capacity(3);
            for level in Level::ALL {
                let mask = load_instance_mask(scene, level, frame_index)?
                    .ok_or(ViewMaskSetError::NoMasks)?;
                levels.push(mask);
            }
            let masks = [&levels[0], &levels[1], &levels[2]];
            views.push(ViewMasks::new(scene, frame_index, masks, max_side)?);
        }
        Ok(Self { views })
    }

    /// Renames object `from` to `to` at `level` in the views from index `first_view` on: the
    /// masks of a tracker that lost the object there and found it again under a new id, which
    /// is what the lost-track merge ([`super::track_merge`]) undoes.
    pub fn rename_from_view(&mut self, first_view: usize, level: Level, from: u32, to: u32) {
        for view in self.views.iter_mut().skip(first_view) {
            view.ids[level.index()]
                .iter_mut()
                .filter(|id| **id == from)
                .for_each(|id| *id = to);
        }
    }

    /// The view of `frame_index`, if it is one of these.
    pub fn view_of_frame(&self, frame_index: usize) -> Option<&ViewMasks> {
        self.views
            .iter()
            .find(|view| view.frame_index == frame_index)
    }
}

fn frame_of(scene: &Scene, frame_index: usize) -> Result<&Frame, ViewMaskSetError> {
    Ok(scene
        .frames
        .get(frame_index)
        .ok_or_else(|| SceneError::Inconsistent {
            file: scene.root.display().to_string(),
            message: format!("frame {frame_index} requested but the scene has fewer"),
        })?)
}

/// Nearest-neighbour resampling (ids must not blend), sampling at pixel centres.
fn downsample_nearest(mask: &InstanceMask, width: u32, height: u32) -> Vec<u32> {
    if (width, height) == (mask.width, mask.height) {
        return mask.ids.clone();
    }
    let source_x: Vec<usize> = (0..width)
        .map(|x| {
            let centre = (x as f64 + 0.5) * f64::from(mask.width) / f64::from(width);
            (centre as usize).min(mask.width as usize - 1)
        })
        .collect();
    (0..height)
        .flat_map(|y| {
            let centre = (y as f64 + 0.5) * f64::from(mask.height) / f64::from(height);
            let row = (centre as usize).min(mask.height as usize - 1) * mask.width as usize;
            source_x.iter().map(move |&x| mask.ids[row + x])
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use segsplat_scene::synthetic::synthetic_objects;

    /// The synthetic three-sphere COLMAP scene with masks at every level, loaded.
    pub(crate) fn synthetic_scene(dir: &std::path::Path, frames: usize) -> Scene {
        segsplat_scene::synthetic::load_three_spheres(dir, frames, 128, 96)
            .expect("synthetic scene")
    }

    #[test]
    fn user_masks_load_downsampled_with_matching_cameras() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = synthetic_scene(dir.path(), 6);
        let frames: Vec<usize> = (0..scene.frames.len()).collect();
        let masks = ViewMaskSet::from_user_masks(&scene, &frames, Some(32)).expect("masks");
        assert_eq!(masks.views.len(), 6);
        let objects = synthetic_objects();
        for view in &masks.views {
            assert_eq!((view.width, view.height), (32, 24));
            assert_eq!((view.camera.width, view.camera.height), (32, 24));
            // Each sphere centre projects onto its own id (spheres are convex and in front).
            for object in &objects {
                if let Some(pixel) = view.pixel_of_point(object.center) {
                    let small = view.ids(Level::Small)[pixel];
                    assert!(small == 0 || objects.iter().any(|o| o.ids[0] == small));
                }
            }
            assert!(!view.objects_at(Level::Large).is_empty());
        }
    }

    #[test]
    fn nearest_downsampling_keeps_ids_exact() {
        let mask = InstanceMask {
            width: 4,
            height: 2,
            ids: vec![1, 1, 7, 7, 1, 1, 7, 7],
        };
        assert_eq!(downsample_nearest(&mask, 2, 1), vec![1, 7]);
    }
}
