//! A CLIP image model and text model are only usable together when they embed into the same
//! space; different widths are the one mismatch a signature shows, and scoring across them
//! would quietly match nothing. Widths come from the declared shapes, or, when a graph leaves
//! the width dynamic, from one run on a blank input.

use super::error::ModelError;
use super::manifest::Preprocess;
use super::session::{InputTensor, ModelSession};

/// Fails when the two models' embedding widths differ.
pub fn check_clip_pair(image: &ModelSession, text: &ModelSession) -> Result<(), ModelError> {
    let image_width = embedding_width(image)?;
    let text_width = embedding_width(text)?;
    if image_width == text_width {
        return Ok(());
    }
    Err(ModelError::Pair(format!(
        "clip_image {} ({}) embeds into {image_width} values but clip_text {} ({}) into \
         {text_width}: they are not a pair, and text queries would match nothing; use the \
         image and text towers of one CLIP model",
        image.entry().name,
        image.entry().file,
        text.entry().name,
        text.entry().file
    )))
}

fn embedding_width(session: &ModelSession) -> Result<usize, ModelError> {
    let entry = session.entry();
    let declared = entry
        .outputs
        .first()
        .and_then(|output| output.shape.get(1))
        .copied()
        .filter(|width| *width > 0);
    if let Some(width) = declared {
        return Ok(width as usize);
    }
    let output = entry.outputs.first().map(|output| output.name.as_str());
    let Some(output) = output else {
        return Err(ModelError::Input(format!("{} lists no output", entry.name)));
    };
    let probed = match &entry.preprocess {
        Preprocess::ClipImage(preprocess) => {
            let side = preprocess.image_size as usize;
            let pixels = vec![0f32; 3 * side * side];
            session.run(
                &[(
                    "pixel_values",
                    InputTensor::F32 {
                        shape: &[1, 3, side, side],
                        data: &pixels,
                    },
                )],
                &[output],
            )?
        }
        Preprocess::ClipText(preprocess) => {
            let ids = vec![0i64; preprocess.context_length];
            session.run(
                &[(
                    "input_ids",
                    InputTensor::I64 {
                        shape: &[1, preprocess.context_length],
                        data: &ids,
                    },
                )],
                &[output],
            )?
        }
        _ => {
            return Err(ModelError::Input(format!(
                "{} is not a CLIP model",
                entry.name
            )));
        }
    };
    probed
        .first()
        .and_then(|tensor| tensor.shape.get(1).copied())
        .ok_or_else(|| ModelError::Output {
            model: entry.name.clone(),
            reason: format!("{output} is not [batch, width]"),
        })
}
