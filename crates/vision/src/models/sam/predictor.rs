//! SAM-family prompting: the encoder runs once per image, the decoder answers prompts in bounded
//! chunks, following docs/models.md (coordinates in the encoder frame, padding point (0, 0) with
//! label -1 unless a box is given, `orig_im_size` = [height, width], every decoder input named
//! like an encoder output fed from the encoder — how SAM 2.1's `high_res_feats_*` flow).

use std::sync::Arc;

use image::RgbImage;

use super::batching::DecoderBatching;
use super::mask_postprocess::upscale_low_res_logits;
use super::preprocess::{EncoderInput, sam_encoder_input};
use crate::models::error::ModelError;
use crate::models::manifest::{
    MaskSource, Preprocess, Role, SamDecoderPreprocess, SamEncoderPreprocess,
};
use crate::models::session::{InputTensor, ModelSession, OutputTensor};
use crate::models::store::ModelStore;
use crate::segment::prompt::{PointMasks, PointPromptSegmenter, PromptError};

/// Side of the decoder's low-resolution mask grid (`mask_input`, `low_res_masks`).
pub const LOW_RES_SIDE: usize = 256;
/// Prompts per decoder run unless configured: 16 full-resolution 4-channel answers at
/// 1000 x 660 are ~170 MB.
pub const DEFAULT_PROMPT_CHUNK: usize = 16;
/// The optional SAM 2 decoder output that says whether the prompt hit an object at all.
pub const OBJECT_SCORE_OUTPUT: &str = "object_score_logits";

/// SAM's point labels, as the decoder reads them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointLabel {
    Background,
    Foreground,
}

impl PointLabel {
    fn value(self) -> f32 {
        match self {
            PointLabel::Background => 0.0,
            PointLabel::Foreground => 1.0,
        }
    }
}

/// One prompt, in pixels of the encoded image.
#[derive(Debug, Clone, Default)]
pub struct SamPrompt {
    pub points: Vec<([f32; 2], PointLabel)>,
    /// `[x0, y0, x1, y1]`.
    pub bounding_box: Option<[f32; 4]>,
    /// Low-resolution logits (`256 x 256`, e.g. a previous answer's `low_res_logits`).
    pub mask_input: Option<Vec<f32>>,
}

/// The decoder's four answers to one prompt (channel 0 single-mask, 1/2/3 small/middle/large).
#[derive(Debug, Clone)]
pub struct SamAnswer {
    /// Full-resolution logits, `height x width` row-major, per channel.
    pub logits: Vec<Vec<f32>>,
    pub predicted_iou: Vec<f32>,
    /// `256 x 256` logits per channel, to feed back as `mask_input`.
    pub low_res_logits: Vec<Vec<f32>>,
    /// SAM 2's object score logit (`object_score_logits`), when the decoder has it.
    pub object_score_logit: Option<f32>,
}

impl SamAnswer {
    /// False when the decoder says the prompt hit no object (SAM 2's object score <= 0); SAM 2's
    /// own trackers then treat every mask channel as empty.
    pub fn object_present(&self) -> bool {
        self.object_score_logit.is_none_or(|score| score > 0.0)
    }
}

/// An image after the encoder: its size and every encoder output by name.
#[derive(Debug, Clone)]
pub struct EncodedImage {
    pub width: u32,
    pub height: u32,
    coordinate_scale: [f32; 2],
    features: Vec<(String, OutputTensor)>,
}

impl EncodedImage {
    /// The encoder output `name` (e.g. `image_embeddings`).
    pub fn feature(&self, name: &str) -> Option<&OutputTensor> {
        self.features
            .iter()
            .find(|(feature, _)| feature == name)
            .map(|(_, tensor)| tensor)
    }

    /// Maps a point in image pixels to the encoder frame.
    pub fn to_encoder_frame(&self, point: [f32; 2]) -> [f32; 2] {
        [
            point[0] * self.coordinate_scale[0],
            point[1] * self.coordinate_scale[1],
        ]
    }
}

/// A SAM-family encoder/decoder pair from a model store; cheap to clone and share.
#[derive(Debug, Clone)]
pub struct SamModel {
    encoder: Arc<ModelSession>,
    decoder: Arc<ModelSession>,
    encoder_preprocess: SamEncoderPreprocess,
    decoder_preprocess: SamDecoderPreprocess,
    batching: DecoderBatching,
    has_object_score: bool,
}

impl SamModel {
    pub fn new(store: &ModelStore) -> Result<SamModel, ModelError> {
        let encoder = store.session(Role::SamEncoder)?;
        let decoder = store.session(Role::SamDecoder)?;
        let (
            Preprocess::SamEncoder(encoder_preprocess),
            Preprocess::SamDecoder(decoder_preprocess),
        ) = (
            encoder.entry().preprocess.clone(),
            decoder.entry().preprocess.clone(),
        )
        else {
            return Err(ModelError::Input(
                "sam_encoder/sam_decoder entries lack their preprocessing".to_string(),
            ));
        };
        let batching = DecoderBatching::of(decoder.entry());
        let has_object_score = decoder
            .entry()
            .outputs
            .iter()
            .any(|spec| spec.name == OBJECT_SCORE_OUTPUT);
        Ok(SamModel {
            encoder,
            decoder,
            encoder_preprocess,
            decoder_preprocess,
            batching,
            has_object_score,
        })
    }

    pub fn encoder_name(&self) -> &str {
        &self.encoder.entry().name
    }

    pub fn decoder_name(&self) -> &str {
        &self.decoder.entry().name
    }

    /// How prompts are grouped into decoder runs.
    pub fn batching(&self) -> DecoderBatching {
        self.batching
    }

    /// Whether the decoder reports SAM 2's object score.
    pub fn has_object_score(&self) -> bool {
        self.has_object_score
    }

    /// Decoder channels of small, middle and large.
    pub fn multimask_channels(&self) -> [usize; 3] {
        self.decoder_preprocess.multimask_channels
    }

    /// Runs the encoder on `image` (RGB8, any size).
    pub fn encode(&self, image: &RgbImage) -> Result<EncodedImage, ModelError> {
        let (width, height) = image.dimensions();
        if width == 0 || height == 0 {
            return Err(ModelError::Input("the image is empty".to_string()));
        }
        let EncoderInput {
            pixels,
            coordinate_scale,
        } = sam_encoder_input(image, &self.encoder_preprocess);
        let size = self.encoder_preprocess.image_size as usize;
        let output_names: Vec<&str> = self
            .encoder
            .entry()
            .outputs
            .iter()
            .map(|spec| spec.name.as_str())
            .collect();
        let outputs = self.encoder.run(
            &[(
                "image",
                InputTensor::F32 {
                    shape: &[1, 3, size, size],
                    data: &pixels,
                },
            )],
            &output_names,
        )?;
        Ok(EncodedImage {
            width,
            height,
            coordinate_scale,
            features: output_names
                .iter()
                .map(|name| (*name).to_string())
                .zip(outputs)
                .collect(),
        })
    }

    /// Answers `prompts` against `image`, up to `chunk` prompts per decoder run where the graph
    /// allows it (see [`DecoderBatching`]); prompts with different numbers of points run apart.
    pub fn predict(
        &self,
        image: &EncodedImage,
        prompts: &[SamPrompt],
        chunk: usize,
    ) -> Result<Vec<SamAnswer>, ModelError> {
        let tokens: Vec<Vec<([f32; 2], f32)>> = prompts
            .iter()
            .map(|prompt| prompt_tokens(image, prompt))
            .collect::<Result<_, _>>()?;
        let counts: Vec<usize> = tokens.iter().map(Vec::len).collect();
        let mut answers = Vec::with_capacity(prompts.len());
        for (start, end) in self.batching.runs(prompts, &counts, chunk) {
            answers.extend(self.decode(image, &tokens[start..end], &prompts[start..end])?);
        }
        Ok(answers)
    }

    fn decode(
        &self,
        image: &EncodedImage,
        tokens: &[Vec<([f32; 2], f32)>],
        prompts: &[SamPrompt],
    ) -> Result<Vec<SamAnswer>, ModelError> {
        let batch = tokens.len();
        let points = tokens[0].len();
        let mut coords = Vec::with_capacity(batch * points * 2);
        let mut labels = Vec::with_capacity(batch * points);
        for prompt in tokens {
            for (point, label) in prompt {
                coords.extend_from_slice(point);
                labels.push(*label);
            }
        }
        let low_res = LOW_RES_SIDE * LOW_RES_SIDE;
        // A broadcast mask prior is one for the whole run: `runs` only groups prompts without
        // one, and a prompt with one runs alone, so its prior is the run's.
        let mask_batch = if self.batching.shared_mask_input {
            1
        } else {
            batch
        };
        let mut mask_input = vec![0f32; mask_batch * low_res];
        let mut has_mask_input = vec![0f32; mask_batch];
        for (index, prompt) in prompts.iter().enumerate().take(mask_batch) {
            if let Some(mask) = &prompt.mask_input {
                if mask.len() != low_res {
                    return Err(ModelError::Input(format!(
                        "mask_input has {} values, expected {LOW_RES_SIDE} x {LOW_RES_SIDE}",
                        mask.len()
                    )));
                }
                mask_input[index * low_res..(index + 1) * low_res].copy_from_slice(mask);
                has_mask_input[index] = 1.0;
            }
        }
        let original_size = [image.height as f32, image.width as f32];
        let coords_shape = [batch, points, 2];
        let labels_shape = [batch, points];
        let mask_shape = [mask_batch, 1, LOW_RES_SIDE, LOW_RES_SIDE];
        let has_mask_shape = [mask_batch];
        let size_shape = [2];
        let mut inputs: Vec<(&str, InputTensor<'_>)> = Vec::new();
        for spec in &self.decoder.entry().inputs {
            let name = spec.name.as_str();
            let tensor = match name {
                "point_coords" => InputTensor::F32 {
                    shape: &coords_shape,
                    data: &coords,
                },
                "point_labels" => InputTensor::F32 {
                    shape: &labels_shape,
                    data: &labels,
                },
                "mask_input" => InputTensor::F32 {
                    shape: &mask_shape,
                    data: &mask_input,
                },
                "has_mask_input" => InputTensor::F32 {
                    shape: &has_mask_shape,
                    data: &has_mask_input,
                },
                "orig_im_size" => InputTensor::F32 {
                    shape: &size_shape,
                    data: &original_size,
                },
                other => {
                    let Some((_, feature)) = image.features.iter().find(|(name, _)| name == other)
                    else {
                        return Err(ModelError::Input(format!(
                            "decoder input {other} is neither a prompt input nor an output of {}",
                            self.encoder_name()
                        )));
                    };
                    InputTensor::F32 {
                        shape: &feature.shape,
                        data: &feature.data,
                    }
                }
            };
            inputs.push((name, tensor));
        }
        let masks_from_graph = self.decoder_preprocess.mask_source == MaskSource::Graph;
        let mut output_names = vec!["iou_predictions", "low_res_masks"];
        if masks_from_graph {
            output_names.push("masks");
        }
        if self.has_object_score {
            output_names.push(OBJECT_SCORE_OUTPUT);
        }
        let mut outputs = self.decoder.run(&inputs, &output_names)?.into_iter();
        let (Some(iou), Some(low_res)) = (outputs.next(), outputs.next()) else {
            return Err(self.output_error("expected iou_predictions and low_res_masks".to_string()));
        };
        let masks = if masks_from_graph {
            outputs.next()
        } else {
            None
        };
        let object_scores = outputs.next();
        self.split_answers(
            image,
            batch,
            DecoderOutputs {
                masks,
                iou,
                low_res,
                object_scores,
            },
        )
    }
}

/// One decoder run's outputs; `masks` is absent when segsplat makes them from `low_res`.
struct DecoderOutputs {
    masks: Option<OutputTensor>,
    iou: OutputTensor,
    low_res: OutputTensor,
    object_scores: Option<OutputTensor>,
}

impl SamModel {
    fn output_error(&self, reason: String) -> ModelError {
        ModelError::Output {
            model: self.decoder_name().to_string(),
            reason,
        }
    }

    fn split_answers(
        &self,
        image: &EncodedImage,
        batch: usize,
        outputs: DecoderOutputs,
    ) -> Result<Vec<SamAnswer>, ModelError> {
        let DecoderOutputs {
            masks,
            iou,
            low_res,
            object_scores,
        } = outputs;
        if iou.shape != [batch, 4] || low_res.shape != [batch, 4, LOW_RES_SIDE, LOW_RES_SIDE] {
            return Err(self.output_error(format!(
                "shapes iou_predictions {:?}, low_res_masks {:?}; expected [{batch}, 4] and \
                 [{batch}, 4, {LOW_RES_SIDE}, {LOW_RES_SIDE}]",
                iou.shape, low_res.shape
            )));
        }
        let expected_masks = [batch, 4, image.height as usize, image.width as usize];
        if let Some(masks) = &masks
            && masks.shape != expected_masks
        {
            return Err(self.output_error(format!(
                "masks have shape {:?}, expected {expected_masks:?}",
                masks.shape
            )));
        }
        if let Some(scores) = &object_scores
            && scores.data.len() != batch
        {
            return Err(self.output_error(format!(
                "{OBJECT_SCORE_OUTPUT} has shape {:?}, expected one score per prompt ({batch})",
                scores.shape
            )));
        }
        let pixels = image.width as usize * image.height as usize;
        let low_res_pixels = LOW_RES_SIDE * LOW_RES_SIDE;
        let low_res_channel = |index: usize, channel: usize| {
            &low_res.data[(index * 4 + channel) * low_res_pixels..][..low_res_pixels]
        };
        let full_channel = |index: usize, channel: usize| match &masks {
            Some(masks) => masks.data[(index * 4 + channel) * pixels..][..pixels].to_vec(),
            None => upscale_low_res_logits(
                low_res_channel(index, channel),
                LOW_RES_SIDE,
                image.width,
                image.height,
                self.encoder_preprocess.resize,
                self.encoder_preprocess.image_size,
            ),
        };
        Ok((0..batch)
            .map(|index| SamAnswer {
                logits: (0..4).map(|channel| full_channel(index, channel)).collect(),
                predicted_iou: iou.data[index * 4..index * 4 + 4].to_vec(),
                low_res_logits: (0..4)
                    .map(|channel| low_res_channel(index, channel).to_vec())
                    .collect(),
                object_score_logit: object_scores.as_ref().map(|scores| scores.data[index]),
            })
            .collect())
    }
}

/// The decoder's points for one prompt in the encoder frame: the points, then the box corners
/// (labels 2, 3), or the padding point (0, 0) with label -1 when there is no box.
fn prompt_tokens(
    image: &EncodedImage,
    prompt: &SamPrompt,
) -> Result<Vec<([f32; 2], f32)>, ModelError> {
    if prompt.points.is_empty() && prompt.bounding_box.is_none() {
        return Err(ModelError::Input(
            "a prompt needs at least one point or a box".to_string(),
        ));
    }
    let mut tokens: Vec<([f32; 2], f32)> = prompt
        .points
        .iter()
        .map(|(point, label)| (image.to_encoder_frame(*point), label.value()))
        .collect();
    match prompt.bounding_box {
        Some([x0, y0, x1, y1]) => {
            tokens.push((image.to_encoder_frame([x0, y0]), 2.0));
            tokens.push((image.to_encoder_frame([x1, y1]), 3.0));
        }
        None => tokens.push(([0.0, 0.0], -1.0)),
    }
    if tokens
        .iter()
        .any(|(point, _)| !point[0].is_finite() || !point[1].is_finite())
    {
        return Err(ModelError::Input(
            "prompt coordinates must be finite".to_string(),
        ));
    }
    Ok(tokens)
}

/// [`SamModel`] plus the current image: the [`PointPromptSegmenter`] the mask generator drives.
#[derive(Debug, Clone)]
pub struct SamPredictor {
    model: SamModel,
    image: Option<Arc<EncodedImage>>,
    chunk: usize,
}

impl SamPredictor {
    pub fn new(model: SamModel) -> SamPredictor {
        SamPredictor {
            model,
            image: None,
            chunk: DEFAULT_PROMPT_CHUNK,
        }
    }

    /// Prompts per decoder run (at least 1).
    pub fn with_chunk(mut self, chunk: usize) -> SamPredictor {
        self.chunk = chunk.max(1);
        self
    }

    pub fn model(&self) -> &SamModel {
        &self.model
    }

    /// Prompts per decoder run.
    pub fn chunk(&self) -> usize {
        self.chunk
    }

    /// The encoding of the image last given to `set_image`.
    pub fn encoded_image(&self) -> Option<&Arc<EncodedImage>> {
        self.image.as_ref()
    }

    /// Arbitrary prompts (points with labels, box, previous mask) against the current image.
    pub fn predict(&self, prompts: &[SamPrompt]) -> Result<Vec<SamAnswer>, ModelError> {
        let image = self.image.as_ref().ok_or_else(|| {
            ModelError::Input("no image has been set before prompting".to_string())
        })?;
        self.model.predict(image, prompts, self.chunk)
    }
}

impl PointPromptSegmenter for SamPredictor {
    fn set_image(&mut self, image: &RgbImage) -> Result<(), PromptError> {
        self.image = None;
        let encoded = self
            .model
            .encode(image)
            .map_err(|error| PromptError::Model(Box::new(error)))?;
        self.image = Some(Arc::new(encoded));
        Ok(())
    }

    fn predict_points(&mut self, points: &[[f32; 2]]) -> Result<Vec<PointMasks>, PromptError> {
        let Some(image) = &self.image else {
            return Err(PromptError::NoImage);
        };
        let prompts: Vec<SamPrompt> = points
            .iter()
            .map(|point| SamPrompt {
                points: vec![(*point, PointLabel::Foreground)],
                ..SamPrompt::default()
            })
            .collect();
        let answers = self
            .model
            .predict(image, &prompts, self.chunk)
            .map_err(|error| PromptError::Model(Box::new(error)))?;
        let [small, middle, large] = self.model.multimask_channels();
        Ok(answers
            .into_iter()
            .map(|mut answer| PointMasks {
                object_present: answer.object_present(),
                predicted_iou: [
                    answer.predicted_iou[small],
                    answer.predicted_iou[middle],
                    answer.predicted_iou[large],
                ],
                logits: [
                    std::mem::take(&mut answer.logits[small]),
                    std::mem::take(&mut answer.logits[middle]),
                    std::mem::take(&mut answer.logits[large]),
                ],
            })
            .collect())
    }
}
