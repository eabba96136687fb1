//! The deformation MLP in plain f64: the ground truth for the WGSL kernels and for the
//! finite-difference tests. Inputs are `[gamma(x), gamma(t)]` per Gaussian; the encoded input is
//! concatenated again after the skip layer.

use super::field::{FieldShape, encode_into};

/// Per Gaussian: the encoded input, every layer's post-activation output, and the head outputs.
#[derive(Debug, Clone)]
pub struct ReferenceActivations {
    pub encoded: Vec<f64>,
    /// `hidden[l]` is layer `l`'s output after ReLU.
    pub hidden: Vec<Vec<f64>>,
    pub head: Vec<f64>,
}

/// `[gamma(x), gamma(t)]`.
pub fn encode(shape: &FieldShape, position: [f64; 3], time: f64) -> Vec<f64> {
    let mut encoded = Vec::with_capacity(shape.encoding_width());
    encode_into(&position, shape.position_frequencies, &mut encoded);
    encode_into(&[time], shape.time_frequencies, &mut encoded);
    encoded
}

fn layer_input(shape: &FieldShape, index: usize, acts: &ReferenceActivations) -> Vec<f64> {
    if index == 0 {
        return acts.encoded.clone();
    }
    let previous = &acts.hidden[index - 1];
    if shape.skip_after > 0 && index == shape.skip_after as usize {
        let mut input = acts.encoded.clone();
        input.extend_from_slice(previous);
        input
    } else {
        previous.clone()
    }
}

/// Runs the field for one Gaussian.
pub fn forward(
    shape: &FieldShape,
    parameters: &[f64],
    position: [f64; 3],
    time: f64,
) -> ReferenceActivations {
    let mut acts = ReferenceActivations {
        encoded: encode(shape, position, time),
        hidden: Vec::new(),
        head: Vec::new(),
    };
    for (index, layer) in shape.layers().iter().enumerate() {
        let input = layer_input(shape, index, &acts);
        let output: Vec<f64> = (0..layer.outputs)
            .map(|o| {
                let row = &parameters[layer.weight_offset + o * layer.inputs..][..layer.inputs];
                let z = parameters[layer.bias_offset + o]
                    + row.iter().zip(&input).map(|(w, x)| w * x).sum::<f64>();
                if layer.relu { z.max(0.0) } else { z }
            })
            .collect();
        if layer.relu {
            acts.hidden.push(output);
        } else {
            acts.head = output;
        }
    }
    acts
}

/// Adds `d loss / d parameters` for one Gaussian into `grad_parameters`, given `d loss / d head`.
/// The input is not differentiated: the released code feeds the field detached positions.
pub fn backward(
    shape: &FieldShape,
    parameters: &[f64],
    acts: &ReferenceActivations,
    grad_head: &[f64],
    grad_parameters: &mut [f64],
) {
    let layers = shape.layers();
    let mut grad_output = grad_head.to_vec();
    for index in (0..layers.len()).rev() {
        let layer = layers[index];
        let input = layer_input(shape, index, acts);
        for o in 0..layer.outputs {
            let g = grad_output[o];
            grad_parameters[layer.bias_offset + o] += g;
            let row = layer.weight_offset + o * layer.inputs;
            for (i, x) in input.iter().enumerate() {
                grad_parameters[row + i] += g * x;
            }
        }
        if index == 0 {
            break;
        }
        // Only the previous layer's part of the input carries a gradient further back.
        let hidden_start = layer.inputs - acts.hidden[index - 1].len();
        let previous = &acts.hidden[index - 1];
        grad_output = (0..previous.len())
            .map(|i| {
                if previous[i] <= 0.0 {
                    return 0.0;
                }
                (0..layer.outputs)
                    .map(|o| {
                        grad_output[o]
                            * parameters[layer.weight_offset + o * layer.inputs + hidden_start + i]
                    })
                    .sum()
            })
            .collect();
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;

    #[test]
    fn parameter_gradients_match_finite_differences() {
        let shape = FieldShape {
            depth: 4,
            width: 6,
            skip_after: 2,
            position_frequencies: 2,
            time_frequencies: 1,
            ..FieldShape::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let parameters: Vec<f64> = shape
            .random_parameters(&mut rng)
            .iter()
            .map(|&p| f64::from(p))
            .collect();
        let weights: Vec<f64> = (0..shape.head_outputs())
            .map(|i| 0.3 - 0.1 * i as f64)
            .collect();
        let (position, time) = ([0.2, -0.4, 0.7], 0.35);
        let objective = |params: &[f64]| -> f64 {
            let acts = forward(&shape, params, position, time);
            acts.head.iter().zip(&weights).map(|(h, w)| h * w).sum()
        };
        let acts = forward(&shape, &parameters, position, time);
        let mut analytic = vec![0.0; parameters.len()];
        backward(&shape, &parameters, &acts, &weights, &mut analytic);
        let h = 1e-6;
        let mut checked_nonzero = 0;
        for i in 0..parameters.len() {
            let mut plus = parameters.clone();
            let mut minus = parameters.clone();
            plus[i] += h;
            minus[i] -= h;
            let numeric = (objective(&plus) - objective(&minus)) / (2.0 * h);
            assert!(
                (numeric - analytic[i]).abs() < 1e-6,
                "parameter {i}: {numeric} vs {}",
                analytic[i]
            );
            if analytic[i].abs() > 1e-9 {
                checked_nonzero += 1;
            }
        }
        assert!(
            checked_nonzero > parameters.len() / 4,
            "only {checked_nonzero} of {} gradients are non-zero",
            parameters.len()
        );
    }
}
