//! One opened model: its manifest entry and an ONNX Runtime session shared by every caller.
//!
//! `ort`'s `Session::run` takes `&mut self` (some execution-provider internals are not thread
//! safe), so calls are serialised by a mutex; each run still uses ONNX Runtime's intra-op threads.

use std::borrow::Cow;
use std::sync::Mutex;

use ort::session::{Session, SessionInputValue};
use ort::value::{Tensor, TensorElementType, ValueType};

use super::error::ModelError;
use super::manifest::{Dtype, ModelEntry};
use super::signature::ActualTensor;

/// A borrowed input tensor.
#[derive(Debug, Clone, Copy)]
pub enum InputTensor<'a> {
    F32 { shape: &'a [usize], data: &'a [f32] },
    I64 { shape: &'a [usize], data: &'a [i64] },
}

/// An output tensor, copied out of ONNX Runtime.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputTensor {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

pub struct ModelSession {
    entry: ModelEntry,
    execution_provider: &'static str,
    session: Mutex<Session>,
}

impl std::fmt::Debug for ModelSession {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ModelSession")
            .field("name", &self.entry.name)
            .field("role", &self.entry.role)
            .field("execution_provider", &self.execution_provider)
            .finish()
    }
}

impl ModelSession {
    pub(crate) fn new(
        entry: ModelEntry,
        session: Session,
        execution_provider: &'static str,
    ) -> Self {
        Self {
            entry,
            execution_provider,
            session: Mutex::new(session),
        }
    }

    pub fn entry(&self) -> &ModelEntry {
        &self.entry
    }

    pub fn execution_provider(&self) -> &'static str {
        self.execution_provider
    }

    /// Runs the model with named inputs and returns the named outputs (all `float32` here).
    pub fn run(
        &self,
        inputs: &[(&str, InputTensor<'_>)],
        outputs: &[&str],
    ) -> Result<Vec<OutputTensor>, ModelError> {
        let failed = |reason: String| ModelError::Inference {
            model: self.entry.name.clone(),
            reason,
        };
        let mut values: Vec<(Cow<'_, str>, SessionInputValue<'_>)> =
            Vec::with_capacity(inputs.len());
        for (name, tensor) in inputs {
            let value: SessionInputValue<'_> = match tensor {
                InputTensor::F32 { shape, data } => {
                    Tensor::from_array((shape.to_vec(), data.to_vec()))
                        .map_err(|error| failed(format!("input {name}: {error}")))?
                        .into()
                }
                InputTensor::I64 { shape, data } => {
                    Tensor::from_array((shape.to_vec(), data.to_vec()))
                        .map_err(|error| failed(format!("input {name}: {error}")))?
                        .into()
                }
            };
            values.push((Cow::Borrowed(*name), value));
        }
        let mut session = self
            .session
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let results = session
            .run(values)
            .map_err(|error| failed(error.to_string()))?;
        let mut copied = Vec::with_capacity(outputs.len());
        for name in outputs {
            let value = results.get(*name).ok_or_else(|| ModelError::Output {
                model: self.entry.name.clone(),
                reason: format!("no output {name}"),
            })?;
            let (shape, data) =
                value
                    .try_extract_tensor::<f32>()
                    .map_err(|error| ModelError::Output {
                        model: self.entry.name.clone(),
                        reason: format!("output {name}: {error}"),
                    })?;
            copied.push(OutputTensor {
                shape: shape.iter().map(|dim| (*dim).max(0) as usize).collect(),
                data: data.to_vec(),
            });
        }
        Ok(copied)
    }
}

/// The session's inputs and outputs as the signature check reads them.
pub(crate) fn actual_signature(session: &Session) -> (Vec<ActualTensor>, Vec<ActualTensor>) {
    let describe = |outlets: &[ort::value::Outlet]| {
        outlets
            .iter()
            .map(|outlet| actual_tensor(outlet.name(), outlet.dtype()))
            .collect()
    };
    (describe(session.inputs()), describe(session.outputs()))
}

fn actual_tensor(name: &str, value_type: &ValueType) -> ActualTensor {
    match value_type {
        ValueType::Tensor { ty, shape, .. } => {
            let dtype = dtype_of(*ty);
            ActualTensor {
                name: name.to_string(),
                dtype,
                type_description: dtype
                    .map(|dtype| dtype.as_str().to_string())
                    .unwrap_or_else(|| format!("{ty:?}")),
                shape: shape.iter().copied().collect(),
            }
        }
        other => ActualTensor {
            name: name.to_string(),
            dtype: None,
            type_description: format!("{other:?} (not a tensor)"),
            shape: Vec::new(),
        },
    }
}

fn dtype_of(element: TensorElementType) -> Option<Dtype> {
    Some(match element {
        TensorElementType::Float32 => Dtype::Float32,
        TensorElementType::Float16 => Dtype::Float16,
        TensorElementType::Float64 => Dtype::Float64,
        TensorElementType::Bfloat16 => Dtype::Bfloat16,
        TensorElementType::Int64 => Dtype::Int64,
        TensorElementType::Int32 => Dtype::Int32,
        TensorElementType::Int16 => Dtype::Int16,
        TensorElementType::Int8 => Dtype::Int8,
        TensorElementType::Uint8 => Dtype::Uint8,
        TensorElementType::Bool => Dtype::Bool,
        _ => return None,
    })
}
