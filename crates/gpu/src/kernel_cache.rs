//! Compiled kernels kept on their device, so a pipeline is compiled once per process.
//!
//! A trainer builds about fifty pipelines, and a service worker builds a trainer per job on
//! the same context: on lavapipe every pipeline is an LLVM compile, and on a GPU driver a SPIR-V
//! one, so without this every job paid for all of them again (issue 38, item 5). A kernel is
//! known by its label, its whole source, its entry point and its constants, so two variants of
//! one kernel (another GEMM layout, native or CAS atomics) are two entries. Only kernels that
//! passed the device's validation are kept: a failed compile fails again next time.

use std::collections::HashMap;
use std::time::Duration;

use crate::Kernel;

/// What tells two compiled kernels apart.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) struct KernelKey {
    pub label: &'static str,
    pub source: String,
    pub entry_point: String,
    /// Each override constant's name and value (as bits: `f64` is not `Hash`).
    pub constants: Vec<(String, u64)>,
}

/// The context's compiled kernels and what building them cost.
#[derive(Debug, Default)]
pub(crate) struct KernelCache {
    entries: HashMap<KernelKey, Kernel>,
    compiles: KernelCompiles,
}

/// Kernels compiled and reused on one context, and the time the compiles took.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct KernelCompiles {
    pub compiled: u64,
    pub reused: u64,
    pub compile_seconds: f64,
}

impl KernelCompiles {
    /// What happened between `earlier` and `self` (both read from one context).
    pub fn since(&self, earlier: &KernelCompiles) -> KernelCompiles {
        KernelCompiles {
            compiled: self.compiled.saturating_sub(earlier.compiled),
            reused: self.reused.saturating_sub(earlier.reused),
            compile_seconds: (self.compile_seconds - earlier.compile_seconds).max(0.0),
        }
    }
}

impl KernelCache {
    /// The kernel compiled earlier under `key`, counted as reused.
    pub fn reuse(&mut self, key: &KernelKey) -> Option<Kernel> {
        let kernel = self.entries.get(key).cloned()?;
        self.compiles.reused += 1;
        Some(kernel)
    }

    /// Keeps a kernel that compiled and validated in `took`.
    pub fn insert(&mut self, key: KernelKey, kernel: Kernel, took: Duration) {
        self.compiles.compiled += 1;
        self.compiles.compile_seconds += took.as_secs_f64();
        self.entries.insert(key, kernel);
    }

    pub fn compiles(&self) -> KernelCompiles {
        self.compiles
    }
}

impl KernelKey {
    pub fn new(
        label: &'static str,
        source: String,
        entry_point: &str,
        constants: &[(&str, f64)],
    ) -> Self {
        Self {
            label,
            source,
            entry_point: entry_point.to_string(),
            constants: constants
                .iter()
                .map(|(name, value)| (name.to_string(), value.to_bits()))
                .collect(),
        }
    }
}
