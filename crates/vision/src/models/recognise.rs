//! What an ONNX graph is, told from its signature alone: the role it can play and its family.
//! `models init` writes manifests from it, and signature errors say first what a file looks
//! like, so a decoder given as an encoder reads as that, not as a list of mismatches.

use super::manifest::{Dtype, Family, Role};
use super::signature::ActualTensor;

/// A role recognised from a graph's inputs and outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Recognised {
    pub role: Role,
    /// `Sam` also stands for MobileSAM: the two share a signature, only the weights differ.
    pub family: Family,
}

impl Recognised {
    /// "a SAM 2 decoder", "a CLIP text model", ...
    pub fn describe(&self) -> String {
        let family = match self.family {
            Family::Clip => "CLIP",
            Family::Sam => "SAM",
            Family::MobileSam => "MobileSAM",
            Family::Sam2 => "SAM 2",
        };
        let part = match self.role {
            Role::ClipImage => "image model",
            Role::ClipText => "text model",
            Role::SamEncoder => "encoder",
            Role::SamDecoder => "decoder",
        };
        format!("a {family} {part}")
    }
}

fn named<'a>(tensors: &'a [ActualTensor], name: &str) -> Option<&'a ActualTensor> {
    tensors.iter().find(|tensor| tensor.name == name)
}

fn is_float(tensor: &ActualTensor) -> bool {
    matches!(
        tensor.dtype,
        Some(Dtype::Float32 | Dtype::Float16 | Dtype::Float64 | Dtype::Bfloat16)
    )
}

/// The role a graph can play, if its signature says so unambiguously.
pub fn recognise(inputs: &[ActualTensor], outputs: &[ActualTensor]) -> Option<Recognised> {
    let sam2 = |tensors: &[ActualTensor]| {
        tensors
            .iter()
            .any(|tensor| tensor.name.starts_with("high_res_feats"))
    };
    let family_of = |tensors: &[ActualTensor]| {
        if sam2(tensors) {
            Family::Sam2
        } else {
            Family::Sam
        }
    };
    if named(inputs, "point_coords").is_some() || named(inputs, "point_labels").is_some() {
        return Some(Recognised {
            role: Role::SamDecoder,
            family: family_of(inputs),
        });
    }
    if named(outputs, "image_embeddings").is_some() && named(inputs, "point_coords").is_none() {
        return Some(Recognised {
            role: Role::SamEncoder,
            family: family_of(outputs),
        });
    }
    let [input] = inputs else {
        return None;
    };
    let embedding_output = outputs
        .iter()
        .any(|output| is_float(output) && output.shape.len() == 2);
    if !embedding_output {
        return None;
    }
    let integer_ids = matches!(input.dtype, Some(Dtype::Int64 | Dtype::Int32));
    if integer_ids && input.shape.len() == 2 {
        return Some(Recognised {
            role: Role::ClipText,
            family: Family::Clip,
        });
    }
    let image_like = input.shape.len() == 4 && matches!(input.shape[1], 3 | -1);
    if is_float(input) && image_like {
        return Some(Recognised {
            role: Role::ClipImage,
            family: Family::Clip,
        });
    }
    None
}

/// "inputs a, b; outputs c" for messages.
pub fn describe_signature(inputs: &[ActualTensor], outputs: &[ActualTensor]) -> String {
    let names = |tensors: &[ActualTensor]| {
        tensors
            .iter()
            .map(|tensor| tensor.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!("inputs {}; outputs {}", names(inputs), names(outputs))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tensor(name: &str, dtype: Dtype, shape: &[i64]) -> ActualTensor {
        ActualTensor {
            name: name.to_string(),
            dtype: Some(dtype),
            type_description: dtype.as_str().to_string(),
            shape: shape.to_vec(),
        }
    }

    #[test]
    fn every_role_is_told_from_its_signature() {
        let f = Dtype::Float32;
        let clip_image = (
            vec![tensor("pixel_values", f, &[-1, 3, 224, 224])],
            vec![tensor("image_embeds", f, &[-1, 512])],
        );
        let clip_text = (
            vec![tensor("input_ids", Dtype::Int64, &[-1, 77])],
            vec![tensor("text_embeds", f, &[-1, 512])],
        );
        let encoder = (
            vec![tensor("image", f, &[1, 3, 1024, 1024])],
            vec![
                tensor("image_embeddings", f, &[1, 256, 64, 64]),
                tensor("high_res_feats_0", f, &[1, 32, 256, 256]),
            ],
        );
        let decoder = (
            vec![
                tensor("image_embeddings", f, &[1, 256, 64, 64]),
                tensor("point_coords", f, &[1, -1, 2]),
            ],
            vec![tensor("masks", f, &[-1, 4, -1, -1])],
        );
        let told = |(inputs, outputs): &(Vec<ActualTensor>, Vec<ActualTensor>)| {
            recognise(inputs, outputs).map(|found| (found.role, found.family))
        };
        assert_eq!(told(&clip_image), Some((Role::ClipImage, Family::Clip)));
        assert_eq!(told(&clip_text), Some((Role::ClipText, Family::Clip)));
        assert_eq!(told(&encoder), Some((Role::SamEncoder, Family::Sam2)));
        assert_eq!(told(&decoder), Some((Role::SamDecoder, Family::Sam)));
        let unknown = (
            vec![tensor("x", f, &[1, 10])],
            vec![tensor("y", f, &[1, 10, 3])],
        );
        assert_eq!(told(&unknown), None);
    }
}
