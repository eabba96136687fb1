//! Does a decoder graph's `masks` output follow `orig_im_size`? segment-anything's own export
//! bakes the crop of its example image into the graph, so its masks are right in size and wrong
//! in content for other aspect ratios. One run on blank features with a portrait size tells:
//! the graph's masks are compared with segsplat's own resize of the same `low_res_masks`.

use crate::models::error::ModelError;
use crate::models::manifest::SamEncoderPreprocess;
use crate::models::session::{InputTensor, ModelSession};

use super::mask_postprocess::upscale_low_res_logits;
use super::predictor::LOW_RES_SIDE;

/// Relative difference above which the graph's masks are not SAM's postprocessing.
const MISMATCH: f32 = 0.05;
/// A portrait image: far from segment-anything's landscape example (1500 x 2250).
const PROBE_HEIGHT: u32 = 400;
const PROBE_WIDTH: u32 = 300;

/// The shape a blank feature input gets: the declared one, dynamic dimensions at SAM's sizes.
fn feature_shape(name: &str, declared: &[i64]) -> Vec<usize> {
    let standard: &[usize] = match name {
        "high_res_feats_0" => &[1, 32, 256, 256],
        "high_res_feats_1" => &[1, 64, 128, 128],
        _ => &[1, 256, 64, 64],
    };
    declared
        .iter()
        .zip(standard)
        .map(|(dim, fallback)| if *dim > 0 { *dim as usize } else { *fallback })
        .collect()
}

/// True when the graph's masks match SAM's postprocessing of its low-resolution masks.
pub fn graph_masks_follow_original_size(
    decoder: &ModelSession,
    encoder: &SamEncoderPreprocess,
) -> Result<bool, ModelError> {
    let frame = encoder.image_size as f32;
    let coords = [frame * 0.4, frame * 0.6, 0.0, 0.0];
    let labels = [1.0f32, -1.0];
    let low_res = LOW_RES_SIDE * LOW_RES_SIDE;
    let mask_input = vec![0f32; low_res];
    let has_mask_input = [0f32];
    let original = [PROBE_HEIGHT as f32, PROBE_WIDTH as f32];
    let features: Vec<(String, Vec<usize>, Vec<f32>)> = decoder
        .entry()
        .inputs
        .iter()
        .filter(|spec| {
            ![
                "point_coords",
                "point_labels",
                "mask_input",
                "has_mask_input",
                "orig_im_size",
            ]
            .contains(&spec.name.as_str())
        })
        .map(|spec| {
            let shape = feature_shape(&spec.name, &spec.shape);
            let zeros = vec![0f32; shape.iter().product()];
            (spec.name.clone(), shape, zeros)
        })
        .collect();
    let mut inputs: Vec<(&str, InputTensor<'_>)> = vec![
        (
            "point_coords",
            InputTensor::F32 {
                shape: &[1, 2, 2],
                data: &coords,
            },
        ),
        (
            "point_labels",
            InputTensor::F32 {
                shape: &[1, 2],
                data: &labels,
            },
        ),
        (
            "mask_input",
            InputTensor::F32 {
                shape: &[1, 1, LOW_RES_SIDE, LOW_RES_SIDE],
                data: &mask_input,
            },
        ),
        (
            "has_mask_input",
            InputTensor::F32 {
                shape: &[1],
                data: &has_mask_input,
            },
        ),
        (
            "orig_im_size",
            InputTensor::F32 {
                shape: &[2],
                data: &original,
            },
        ),
    ];
    for (name, shape, data) in &features {
        inputs.push((name, InputTensor::F32 { shape, data }));
    }
    let outputs = decoder.run(&inputs, &["masks", "low_res_masks"])?;
    let [masks, low] = outputs.as_slice() else {
        return Err(ModelError::Output {
            model: decoder.entry().name.clone(),
            reason: "expected masks and low_res_masks".to_string(),
        });
    };
    let pixels = (PROBE_HEIGHT * PROBE_WIDTH) as usize;
    if masks.data.len() != 4 * pixels || low.data.len() != 4 * low_res {
        return Err(ModelError::Output {
            model: decoder.entry().name.clone(),
            reason: format!(
                "masks {:?} and low_res_masks {:?} for one prompt at {PROBE_HEIGHT} x {PROBE_WIDTH}",
                masks.shape, low.shape
            ),
        });
    }
    let mut worst = 0f32;
    for channel in 0..4 {
        let ours = upscale_low_res_logits(
            &low.data[channel * low_res..][..low_res],
            LOW_RES_SIDE,
            PROBE_WIDTH,
            PROBE_HEIGHT,
            encoder.resize,
            encoder.image_size,
        );
        let theirs = &masks.data[channel * pixels..][..pixels];
        let scale = theirs
            .iter()
            .fold(1f32, |most, value| most.max(value.abs()));
        let difference = ours
            .iter()
            .zip(theirs)
            .fold(0f32, |most, (a, b)| most.max((a - b).abs()));
        worst = worst.max(difference / scale);
    }
    Ok(worst <= MISMATCH)
}
