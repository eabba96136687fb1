//! Signature checks: the manifest against what a role needs (docs/models.md), and the ONNX
//! session against the manifest. Each problem is one sentence naming the tensor and the difference.

use super::manifest::{Dtype, Family, ModelEntry, Preprocess, Role, TensorSpec};

/// One expected dimension of a role's tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExpectedDim {
    /// Anything (batch, points, image size, embedding width).
    Any,
    /// This value; a dynamic dimension (-1) also fits.
    Fixed(i64),
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExpectedTensor {
    pub name: String,
    pub dtype: Dtype,
    pub shape: Vec<ExpectedDim>,
}

fn expected(name: &str, dtype: Dtype, shape: &[ExpectedDim]) -> ExpectedTensor {
    ExpectedTensor {
        name: name.to_string(),
        dtype,
        shape: shape.to_vec(),
    }
}

/// The inputs and outputs a role must have, given its family and preprocessing.
pub fn role_signature(entry: &ModelEntry) -> (Vec<ExpectedTensor>, Vec<ExpectedTensor>) {
    use ExpectedDim::{Any, Fixed};
    let f32 = Dtype::Float32;
    match &entry.preprocess {
        Preprocess::ClipImage(p) => {
            let size = i64::from(p.image_size);
            (
                vec![expected(
                    "pixel_values",
                    f32,
                    &[Any, Fixed(3), Fixed(size), Fixed(size)],
                )],
                vec![expected("image_embeds", f32, &[Any, Any])],
            )
        }
        Preprocess::ClipText(p) => (
            vec![expected(
                "input_ids",
                Dtype::Int64,
                &[Any, Fixed(p.context_length as i64)],
            )],
            vec![expected("text_embeds", f32, &[Any, Any])],
        ),
        Preprocess::SamEncoder(p) => {
            let size = i64::from(p.image_size);
            let mut outputs = vec![expected(
                "image_embeddings",
                f32,
                &[Fixed(1), Fixed(256), Fixed(size / 16), Fixed(size / 16)],
            )];
            if entry.family == Family::Sam2 {
                outputs.extend(sam2_high_res_features(size));
            }
            (
                vec![expected(
                    "image",
                    f32,
                    &[Fixed(1), Fixed(3), Fixed(size), Fixed(size)],
                )],
                outputs,
            )
        }
        Preprocess::SamDecoder(_) => {
            // The decoder does not know the encoder's input size; 1024 is the only size the
            // SAM family is trained at, so the embedding grid is 64 x 64.
            let mut inputs = vec![
                expected(
                    "image_embeddings",
                    f32,
                    &[Fixed(1), Fixed(256), Fixed(64), Fixed(64)],
                ),
                expected("point_coords", f32, &[Any, Any, Fixed(2)]),
                expected("point_labels", f32, &[Any, Any]),
                expected("mask_input", f32, &[Any, Fixed(1), Fixed(256), Fixed(256)]),
                expected("has_mask_input", f32, &[Any]),
                expected("orig_im_size", f32, &[Fixed(2)]),
            ];
            if entry.family == Family::Sam2 {
                inputs.extend(sam2_high_res_features(1024));
            }
            (
                inputs,
                vec![
                    expected("masks", f32, &[Any, Fixed(4), Any, Any]),
                    expected("iou_predictions", f32, &[Any, Fixed(4)]),
                    expected(
                        "low_res_masks",
                        f32,
                        &[Any, Fixed(4), Fixed(256), Fixed(256)],
                    ),
                ],
            )
        }
    }
}

/// Outputs a role may have and segsplat reads when present: SAM 2's decoders report an object
/// score per prompt (`> 0`: the prompt hit an object).
pub fn optional_outputs(entry: &ModelEntry) -> Vec<ExpectedTensor> {
    use ExpectedDim::{Any, Fixed};
    match entry.preprocess {
        Preprocess::SamDecoder(_) => vec![expected(
            "object_score_logits",
            Dtype::Float32,
            &[Any, Fixed(1)],
        )],
        _ => Vec::new(),
    }
}

fn sam2_high_res_features(image_size: i64) -> [ExpectedTensor; 2] {
    use ExpectedDim::Fixed;
    [
        expected(
            "high_res_feats_0",
            Dtype::Float32,
            &[
                Fixed(1),
                Fixed(32),
                Fixed(image_size / 4),
                Fixed(image_size / 4),
            ],
        ),
        expected(
            "high_res_feats_1",
            Dtype::Float32,
            &[
                Fixed(1),
                Fixed(64),
                Fixed(image_size / 8),
                Fixed(image_size / 8),
            ],
        ),
    ]
}

/// The outcome of a signature comparison: problems make the model unusable; notes are worth
/// telling (outputs segsplat does not read, optional outputs it will use).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SignatureCheck {
    pub problems: Vec<String>,
    pub notes: Vec<String>,
}

impl SignatureCheck {
    pub fn is_ok(&self) -> bool {
        self.problems.is_empty()
    }
}

/// The manifest's signature against the role's.
pub fn manifest_vs_role(entry: &ModelEntry) -> SignatureCheck {
    let (inputs, outputs) = role_signature(entry);
    let optional = optional_outputs(entry);
    let mut check = SignatureCheck::default();
    compare_expected("input", &inputs, &[], &entry.inputs, entry.role, &mut check);
    compare_expected(
        "output",
        &outputs,
        &optional,
        &entry.outputs,
        entry.role,
        &mut check,
    );
    check
}

fn compare_expected(
    kind: &str,
    expected: &[ExpectedTensor],
    optional: &[ExpectedTensor],
    declared: &[TensorSpec],
    role: Role,
    check: &mut SignatureCheck,
) {
    for want in expected {
        let Some(have) = declared.iter().find(|spec| spec.name == want.name) else {
            check.problems.push(format!(
                "manifest lacks {kind} {} that a {role} needs",
                want.name
            ));
            continue;
        };
        compare_spec(kind, want, have, role, &mut check.problems);
    }
    for have in declared {
        if expected.iter().any(|want| want.name == have.name) {
            continue;
        }
        if let Some(want) = optional.iter().find(|want| want.name == have.name) {
            compare_spec(kind, want, have, role, &mut check.problems);
            check
                .notes
                .push(format!("optional {kind} {} is read", have.name));
        } else if kind == "output" {
            // Outputs are fetched by name, so one segsplat does not read costs nothing.
            check
                .notes
                .push(format!("extra {kind} {} is not read", have.name));
        } else {
            check.problems.push(format!(
                "manifest {kind} {} is not part of a {role}'s signature (segsplat cannot feed it)",
                have.name
            ));
        }
    }
}

fn compare_spec(
    kind: &str,
    want: &ExpectedTensor,
    have: &TensorSpec,
    role: Role,
    problems: &mut Vec<String>,
) {
    if have.dtype != want.dtype {
        problems.push(format!(
            "manifest {kind} {} has dtype {}, a {role} needs {}",
            want.name, have.dtype, want.dtype
        ));
    }
    if have.shape.len() != want.shape.len() {
        problems.push(format!(
            "manifest {kind} {} has rank {} ({:?}), a {role} needs rank {}",
            want.name,
            have.shape.len(),
            have.shape,
            want.shape.len()
        ));
        return;
    }
    for (axis, (have_dim, want_dim)) in have.shape.iter().zip(&want.shape).enumerate() {
        if let ExpectedDim::Fixed(value) = want_dim
            && *have_dim != *value
            && *have_dim != -1
        {
            problems.push(format!(
                "manifest {kind} {} has dimension {axis} = {have_dim}, a {role} needs {value}",
                want.name
            ));
        }
    }
}

/// What the ONNX session reports for one input or output.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ActualTensor {
    pub name: String,
    /// `None` for an element type outside [`Dtype`], or a non-tensor value.
    pub dtype: Option<Dtype>,
    /// How ONNX Runtime names the type (for messages about types segsplat does not know).
    pub type_description: String,
    pub shape: Vec<i64>,
}

/// The session's actual signature against the manifest. Outputs the manifest leaves out are
/// notes, not problems: segsplat fetches outputs by name.
pub fn session_vs_manifest(
    entry: &ModelEntry,
    actual_inputs: &[ActualTensor],
    actual_outputs: &[ActualTensor],
) -> SignatureCheck {
    let mut check = SignatureCheck::default();
    compare_actual("input", &entry.inputs, actual_inputs, &mut check);
    compare_actual("output", &entry.outputs, actual_outputs, &mut check);
    check
}

fn compare_actual(
    kind: &str,
    declared: &[TensorSpec],
    actual: &[ActualTensor],
    check: &mut SignatureCheck,
) {
    let problems = &mut check.problems;
    for spec in declared {
        let Some(have) = actual.iter().find(|tensor| tensor.name == spec.name) else {
            let names: Vec<&str> = actual.iter().map(|tensor| tensor.name.as_str()).collect();
            problems.push(format!(
                "model has no {kind} {} (its {kind}s: {})",
                spec.name,
                names.join(", ")
            ));
            continue;
        };
        if have.dtype != Some(spec.dtype) {
            problems.push(format!(
                "{kind} {} has dtype {}, manifest says {}",
                spec.name, have.type_description, spec.dtype
            ));
        }
        if have.shape.len() != spec.shape.len() {
            problems.push(format!(
                "{kind} {} has rank {} ({:?}), manifest says rank {} ({:?})",
                spec.name,
                have.shape.len(),
                have.shape,
                spec.shape.len(),
                spec.shape
            ));
            continue;
        }
        for (axis, (have_dim, spec_dim)) in have.shape.iter().zip(&spec.shape).enumerate() {
            // A fixed manifest dimension fits a dynamic model dimension; a dynamic manifest
            // dimension (e.g. batch) does not fit a fixed one: callers would send other sizes.
            let fits = *have_dim == *spec_dim || (*spec_dim >= 0 && *have_dim < 0);
            if !fits {
                problems.push(format!(
                    "{kind} {} has dimension {axis} = {}, manifest says {}",
                    spec.name,
                    describe_dim(*have_dim),
                    describe_dim(*spec_dim)
                ));
            }
        }
    }
    for have in actual {
        if declared.iter().any(|spec| spec.name == have.name) {
            continue;
        }
        if kind == "output" {
            check.notes.push(format!(
                "model output {} is not in the manifest and is not read",
                have.name
            ));
        } else {
            problems.push(format!(
                "model has {kind} {} that the manifest does not list",
                have.name
            ));
        }
    }
}

fn describe_dim(dim: i64) -> String {
    if dim < 0 {
        "dynamic".to_string()
    } else {
        dim.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::manifest::{ClipTextPreprocess, Preprocess};

    fn text_entry(inputs: Vec<TensorSpec>) -> ModelEntry {
        ModelEntry {
            name: "text".to_string(),
            role: Role::ClipText,
            family: Family::Clip,
            architecture: "test".to_string(),
            file: "text.onnx".to_string(),
            sha256: "0".repeat(64),
            size: None,
            inputs,
            outputs: vec![TensorSpec {
                name: "text_embeds".to_string(),
                dtype: Dtype::Float32,
                shape: vec![-1, 512],
            }],
            preprocess: Preprocess::ClipText(ClipTextPreprocess {
                context_length: 77,
                output_normalized: false,
            }),
        }
    }

    fn ids(dtype: Dtype, shape: Vec<i64>) -> TensorSpec {
        TensorSpec {
            name: "input_ids".to_string(),
            dtype,
            shape,
        }
    }

    #[test]
    fn role_check_names_dtype_and_fixed_dimension() {
        assert!(manifest_vs_role(&text_entry(vec![ids(Dtype::Int64, vec![-1, 77])])).is_ok());
        let problems =
            manifest_vs_role(&text_entry(vec![ids(Dtype::Int32, vec![-1, 76])])).problems;
        assert_eq!(
            problems,
            vec![
                "manifest input input_ids has dtype int32, a clip_text needs int64".to_string(),
                "manifest input input_ids has dimension 1 = 76, a clip_text needs 77".to_string(),
            ]
        );
    }

    #[test]
    fn session_check_accepts_dynamic_for_fixed_but_not_the_reverse() {
        let entry = text_entry(vec![ids(Dtype::Int64, vec![-1, 77])]);
        let actual = |shape: Vec<i64>| ActualTensor {
            name: "input_ids".to_string(),
            dtype: Some(Dtype::Int64),
            type_description: "int64".to_string(),
            shape,
        };
        let outputs = [ActualTensor {
            name: "text_embeds".to_string(),
            dtype: Some(Dtype::Float32),
            type_description: "float32".to_string(),
            shape: vec![-1, 512],
        }];
        assert!(session_vs_manifest(&entry, &[actual(vec![-1, -1])], &outputs).is_ok());
        assert_eq!(
            session_vs_manifest(&entry, &[actual(vec![1, 77])], &outputs).problems,
            vec!["input input_ids has dimension 0 = 1, manifest says dynamic".to_string()]
        );
    }
}
