//! The training and evaluation views of a scene: cameras at the training resolution and the
//! target images, resident on the GPU in the renderer's image layout (`vec4<f32>` per pixel).

use crate::camera::{CameraError, RenderCamera};
use image::Rgb32FImage;
use image::imageops::FilterType;
use rayon::prelude::*;
use segsplat_gpu::GpuContext;
use segsplat_scene::{FrameSplit, Scene, SceneError, load_frame_rgb};

#[derive(Debug, thiserror::Error)]
pub enum ViewsError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error("frame {frame:?}: image is {image:?} but its camera at that scale is {camera:?}")]
    SizeMismatch {
        frame: String,
        image: [u32; 2],
        camera: [u32; 2],
    },
    #[error("the scene has no training views")]
    NoTrainingViews,
}

/// One view: its camera, target image on the GPU, and a CPU copy for evaluation.
pub struct View {
    pub frame_index: usize,
    pub name: String,
    pub camera: RenderCamera,
    /// The frame's normalised capture time (0 for static scenes).
    pub time: f32,
    /// `width * height` vec4 (rgb, 1), row-major.
    pub target: wgpu::Buffer,
    /// RGB, row-major; kept for held-out views only (evaluation), empty otherwise.
    pub target_rgb: Vec<[f32; 3]>,
    /// The view at half, quarter, ... resolution for the coarse steps of training
    /// ([`crate::train::TrainSchedule::resolution_divisor_at`]): entry `k` is `2^(k+1)` times
    /// smaller each way. Training views only; empty when the schedule has no coarse steps.
    pub coarse: Vec<CoarseView>,
}

/// A training view at reduced resolution: its camera ([`RenderCamera::downscaled`]) and the target
/// image filtered down to it.
pub struct CoarseView {
    pub divisor: u32,
    pub camera: RenderCamera,
    pub target: wgpu::Buffer,
}

impl View {
    /// The camera and target to train on at `divisor` (1: full resolution; a divisor the view has
    /// no coarse image for falls back to full resolution).
    pub fn at_divisor(&self, divisor: u32) -> (&RenderCamera, &wgpu::Buffer) {
        self.coarse
            .iter()
            .find(|coarse| coarse.divisor == divisor)
            .map_or((&self.camera, &self.target), |coarse| {
                (&coarse.camera, &coarse.target)
            })
    }
}

pub struct Views {
    pub train: Vec<View>,
    pub test: Vec<View>,
}

/// Which frames are held out: the dataset's own test (or val) split when it has one (a Blender
/// upload's `transforms_test.json`; `split_every` is then not used), else every
/// `split_every`-th frame in capture order (the first included), as 3DGS does. An upload with
/// only `transforms_train.json` is held out every `split_every`-th frame like any other.
pub fn is_held_out(scene: &Scene, frame_index: usize, split_every: u32) -> bool {
    let own_split = scene
        .frames
        .iter()
        .any(|f| matches!(f.split, Some(FrameSplit::Test) | Some(FrameSplit::Val)));
    if own_split {
        return matches!(
            scene.frames[frame_index].split,
            Some(FrameSplit::Test) | Some(FrameSplit::Val)
        );
    }
    split_every > 0 && frame_index.is_multiple_of(split_every as usize)
}

/// Pixels of the training views (every frame not held out) at `max_resolution`, from the
/// frames' sizes, without loading their images.
pub fn training_pixels(scene: &Scene, max_resolution: Option<u32>, split_every: u32) -> u64 {
    scene
        .frames
        .iter()
        .enumerate()
        .filter(|(index, _)| !is_held_out(scene, *index, split_every))
        .map(|(_, frame)| {
            let (width, height) = (frame.intrinsics.width, frame.intrinsics.height);
            let factor = max_resolution.map_or(1.0, |side| {
                segsplat_scene::scale_for_max_side(width, height, side)
            });
            let (width, height) = segsplat_scene::scaled_size(width, height, factor);
            width as u64 * height as u64
        })
        .sum()
}

impl Views {
    /// Loads every frame at `max_resolution`; training views also get `coarse_halvings` coarse
    /// images ([`View::coarse`]).
    ///
    /// Frames are decoded and filtered on every core, as many at a time as rayon has threads,
    /// and uploaded in capture order: the host holds one batch of images, not the whole scene
    /// (issue 38, item 5: a job's setup decoded its views one at a time, on one core).
    pub fn load(
        ctx: &GpuContext,
        scene: &Scene,
        max_resolution: Option<u32>,
        split_every: u32,
        coarse_halvings: u32,
    ) -> Result<Self, ViewsError> {
        let mut views = Views {
            train: Vec::new(),
            test: Vec::new(),
        };
        let batch = rayon::current_num_threads().max(1);
        for start in (0..scene.frames.len()).step_by(batch) {
            let end = (start + batch).min(scene.frames.len());
            let decoded: Vec<Result<DecodedView, ViewsError>> = (start..end)
                .into_par_iter()
                .map(|frame_index| {
                    DecodedView::decode(
                        scene,
                        frame_index,
                        max_resolution,
                        split_every,
                        coarse_halvings,
                    )
                })
                .collect();
            for view in decoded {
                let view = view?;
                let held_out = view.held_out;
                let view = view.upload(ctx);
                if held_out {
                    views.test.push(view);
                } else {
                    views.train.push(view);
                }
            }
        }
        if views.train.is_empty() {
            return Err(ViewsError::NoTrainingViews);
        }
        Ok(views)
    }

    /// Largest image in pixels (sizes the loss scratch buffers).
    pub fn max_size(&self) -> [u32; 2] {
        self.train
            .iter()
            .chain(&self.test)
            .fold([1, 1], |[w, h], v| {
                [w.max(v.camera.width), h.max(v.camera.height)]
            })
    }
}

fn rgba_pixels(image: &Rgb32FImage) -> Vec<[f32; 4]> {
    image.pixels().map(|p| [p[0], p[1], p[2], 1.0]).collect()
}

/// One frame's images decoded and filtered on the CPU, not yet on the GPU.
struct DecodedView {
    frame_index: usize,
    name: String,
    time: f32,
    held_out: bool,
    camera: RenderCamera,
    pixels: Vec<[f32; 4]>,
    /// One per coarse level; training views only.
    coarse: Vec<DecodedCoarse>,
}

/// A [`CoarseView`] before its upload.
struct DecodedCoarse {
    divisor: u32,
    camera: RenderCamera,
    pixels: Vec<[f32; 4]>,
}

impl DecodedView {
    fn decode(
        scene: &Scene,
        frame_index: usize,
        max_resolution: Option<u32>,
        split_every: u32,
        coarse_halvings: u32,
    ) -> Result<Self, ViewsError> {
        let frame = &scene.frames[frame_index];
        let held_out = is_held_out(scene, frame_index, split_every);
        let image = load_frame_rgb(scene, frame_index, max_resolution)?;
        let (width, height) = image.dimensions();
        let scale = width as f32 / frame.intrinsics.width as f32;
        let camera = RenderCamera::from_frame(frame, scale)?;
        if (camera.width, camera.height) != (width, height) {
            return Err(ViewsError::SizeMismatch {
                frame: frame.name.clone(),
                image: [width, height],
                camera: [camera.width, camera.height],
            });
        }
        let coarse = if held_out {
            Vec::new()
        } else {
            (1..=coarse_halvings)
                .map(|halvings| coarse_image(&camera, &image, 1 << halvings))
                .collect()
        };
        Ok(Self {
            frame_index,
            name: frame.name.clone(),
            time: frame.time.unwrap_or(0.0),
            held_out,
            camera,
            pixels: rgba_pixels(&image),
            coarse,
        })
    }

    fn upload(self, ctx: &GpuContext) -> View {
        View {
            frame_index: self.frame_index,
            name: self.name,
            camera: self.camera,
            time: self.time,
            target: upload_target(ctx, &self.pixels),
            target_rgb: if self.held_out {
                self.pixels.iter().map(|p| [p[0], p[1], p[2]]).collect()
            } else {
                Vec::new()
            },
            coarse: self
                .coarse
                .into_iter()
                .map(|coarse| CoarseView {
                    divisor: coarse.divisor,
                    camera: coarse.camera,
                    target: upload_target(ctx, &coarse.pixels),
                })
                .collect(),
        }
    }
}

fn upload_target(ctx: &GpuContext, pixels: &[[f32; 4]]) -> wgpu::Buffer {
    wgpu::util::DeviceExt::create_buffer_init(
        &ctx.device,
        &wgpu::util::BufferInitDescriptor {
            label: Some("target image"),
            contents: bytemuck::cast_slice(pixels),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        },
    )
}

/// `image` filtered down to `camera` made `divisor` times smaller. The triangle filter widens
/// with the reduction, so each coarse pixel averages the block it covers (no aliasing, and no
/// ringing that would ask the splats for colours outside 0..1).
fn coarse_image(camera: &RenderCamera, image: &Rgb32FImage, divisor: u32) -> DecodedCoarse {
    let camera = camera.downscaled(divisor);
    let reduced = image::imageops::resize(image, camera.width, camera.height, FilterType::Triangle);
    DecodedCoarse {
        divisor,
        camera,
        pixels: rgba_pixels(&reduced),
    }
}
