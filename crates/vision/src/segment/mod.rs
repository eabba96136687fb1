//! segment: mask generators (SAM-family automatic masks, classical fallback, user-provided),
//! tracking, de-duplication and merging. See docs/segment.md.
//!
//! Every generator answers [`FrameMasks`]: per level (small, middle, large) a list of
//! [`ScoredMask`]s, best first, as compact bitsets ([`BitMask`]) that convert to COCO RLE.

pub mod automatic;
pub mod classical;
mod felzenszwalb;
pub mod mask;
pub mod nms;
pub mod prompt;
pub mod propagation;
pub mod region_prompt;
pub mod regions;
pub mod rle;
pub mod scored;
pub mod user;

use std::sync::Arc;

use image::RgbImage;

pub use automatic::{AutomaticConfig, AutomaticError, generate_automatic_masks, postprocess_level};
pub use classical::{ClassicalConfig, ClassicalError, classical_masks};
pub use mask::{BitMask, BoundingBox, MaskError};
pub use nms::MaskNmsConfig;
pub use prompt::{PointMasks, PointPromptSegmenter, PromptError};
pub use propagation::{
    FirstFrameMasks, Propagation, PropagationError, PropagationOptions, PropagationReport,
    propagate_masks,
};
pub use region_prompt::{RegionAnswer, RegionPrompt, RegionPromptSegmenter};
pub use rle::{CocoRle, CompressedRle, RleError};
pub use scored::{FrameMasks, ScoredMask, instance_ids_from_masks};
pub use user::{UserMaskError, user_frame_masks};

use segsplat_scene::Scene;

/// Any failure of a mask generator.
#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    #[error(transparent)]
    Automatic(#[from] AutomaticError),
    #[error(transparent)]
    Classical(#[from] ClassicalError),
    #[error(transparent)]
    User(#[from] UserMaskError),
    #[error(
        "user mask for frame {frame_index} is {mask_width}x{mask_height}, the image {image_width}x{image_height}"
    )]
    UserMaskSize {
        frame_index: usize,
        mask_width: u32,
        mask_height: u32,
        image_width: u32,
        image_height: u32,
    },
}

/// A [`MaskGenerator`] with no state (see [`MaskGenerator::stateless`]), so frames can be
/// segmented on several threads at once.
#[derive(Clone, Copy)]
pub enum StatelessGenerator<'a> {
    Classical(&'a ClassicalConfig),
    User(&'a Arc<Scene>),
}

impl StatelessGenerator<'_> {
    /// As [`MaskGenerator::generate`].
    pub fn generate(
        &self,
        image: &RgbImage,
        frame_index: usize,
    ) -> Result<FrameMasks, SegmentError> {
        match *self {
            StatelessGenerator::Classical(config) => Ok(classical_masks(image, config)?),
            StatelessGenerator::User(scene) => {
                let frame = user_frame_masks(scene, frame_index)?;
                let mismatch = frame.levels.iter().flatten().find(|scored| {
                    (scored.mask.width(), scored.mask.height()) != image.dimensions()
                });
                if let Some(scored) = mismatch {
                    return Err(SegmentError::UserMaskSize {
                        frame_index,
                        mask_width: scored.mask.width(),
                        mask_height: scored.mask.height(),
                        image_width: image.width(),
                        image_height: image.height(),
                    });
                }
                Ok(frame)
            }
        }
    }
}

/// Where a frame's masks come from.
pub enum MaskGenerator {
    /// Automatic masks from a point-prompt model (SAM family).
    Automatic {
        segmenter: Box<dyn PointPromptSegmenter + Send>,
        config: AutomaticConfig,
    },
    /// The model-free fallback.
    Classical(ClassicalConfig),
    /// The scene's own instance-id masks; segmentation is skipped.
    User(Arc<Scene>),
}

impl MaskGenerator {
    /// The masks of frame `frame_index`, whose pixels are `image`. Automatic and classical
    /// generators look only at `image`; user masks only at the frame index (their size must
    /// match `image`, so masks and pixels line up).
    pub fn generate(
        &mut self,
        image: &RgbImage,
        frame_index: usize,
    ) -> Result<FrameMasks, SegmentError> {
        match self {
            MaskGenerator::Automatic { segmenter, config } => {
                Ok(generate_automatic_masks(segmenter.as_mut(), image, config)?)
            }
            MaskGenerator::Classical(config) => {
                StatelessGenerator::Classical(config).generate(image, frame_index)
            }
            MaskGenerator::User(scene) => {
                StatelessGenerator::User(scene).generate(image, frame_index)
            }
        }
    }

    /// This generator as one that many threads can use at once, when it holds no state: the
    /// classical and user generators. A model's session segments one frame at a time (and
    /// spreads each frame's work over the cores itself).
    pub fn stateless(&self) -> Option<StatelessGenerator<'_>> {
        match self {
            MaskGenerator::Automatic { .. } => None,
            MaskGenerator::Classical(config) => Some(StatelessGenerator::Classical(config)),
            MaskGenerator::User(scene) => Some(StatelessGenerator::User(scene)),
        }
    }

    /// A short name for logs and job records.
    pub fn kind(&self) -> &'static str {
        match self {
            MaskGenerator::Automatic { .. } => "automatic",
            MaskGenerator::Classical(_) => "classical",
            MaskGenerator::User(_) => "user",
        }
    }
}
