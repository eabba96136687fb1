//! A trained deformation field on disk: `deformation.json` (the field's shape and parameter
//! count) next to `deformation.bin` (the flat parameters, f32 little-endian, in
//! [`super::field`]'s layout). Written with a dynamic scene's `scene.ply`, which holds the
//! canonical Gaussians the field moves.

use serde::{Deserialize, Serialize};

use super::field::FieldShape;

pub const DEFORMATION_FILE: &str = "deformation.json";
pub const DEFORMATION_WEIGHTS_FILE: &str = "deformation.bin";

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeformationHeader {
    pub field: FieldShape,
    pub parameter_count: usize,
    /// The span of training times (normalised capture time), for callers choosing a `t`.
    pub time_range: [f32; 2],
}

/// A field as stored: its shape and weights.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredDeformation {
    pub header: DeformationHeader,
    pub parameters: Vec<f32>,
}

#[derive(Debug, thiserror::Error)]
pub enum DeformationFileError {
    #[error("{DEFORMATION_FILE}: {0}")]
    Header(String),
    #[error("{DEFORMATION_WEIGHTS_FILE}: {0}")]
    Weights(String),
}

impl StoredDeformation {
    pub fn header_bytes(&self) -> Result<Vec<u8>, DeformationFileError> {
        serde_json::to_vec_pretty(&self.header)
            .map_err(|error| DeformationFileError::Header(error.to_string()))
    }

    pub fn weight_bytes(&self) -> Vec<u8> {
        self.parameters
            .iter()
            .flat_map(|value| value.to_le_bytes())
            .collect()
    }

    /// Parses both files, checking the weights match the shape.
    pub fn parse(header: &[u8], weights: &[u8]) -> Result<Self, DeformationFileError> {
        let header: DeformationHeader = serde_json::from_slice(header)
            .map_err(|error| DeformationFileError::Header(error.to_string()))?;
        header
            .field
            .validate()
            .map_err(DeformationFileError::Header)?;
        let expected = header.field.parameter_count();
        if header.parameter_count != expected {
            return Err(DeformationFileError::Header(format!(
                "parameter_count {} does not match the field shape ({expected})",
                header.parameter_count
            )));
        }
        if weights.len() != expected * 4 {
            return Err(DeformationFileError::Weights(format!(
                "{} bytes, expected {} ({expected} f32)",
                weights.len(),
                expected * 4
            )));
        }
        let parameters: Vec<f32> = weights
            .chunks_exact(4)
            .map(|bytes| f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
            .collect();
        if parameters.iter().any(|value| !value.is_finite()) {
            return Err(DeformationFileError::Weights(
                "weights must be finite".to_string(),
            ));
        }
        Ok(Self { header, parameters })
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;

    #[test]
    fn round_trip_and_mismatches_are_named() {
        let field = FieldShape {
            depth: 4,
            width: 8,
            skip_after: 2,
            ..FieldShape::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let stored = StoredDeformation {
            header: DeformationHeader {
                field,
                parameter_count: field.parameter_count(),
                time_range: [0.0, 1.0],
            },
            parameters: field.random_parameters(&mut rng),
        };
        let header = stored.header_bytes().unwrap();
        let weights = stored.weight_bytes();
        assert_eq!(StoredDeformation::parse(&header, &weights).unwrap(), stored);
        let error = StoredDeformation::parse(&header, &weights[4..]).unwrap_err();
        assert!(error.to_string().contains(DEFORMATION_WEIGHTS_FILE));
        let error = StoredDeformation::parse(b"{}", &weights).unwrap_err();
        assert!(error.to_string().contains(DEFORMATION_FILE));
    }
}
