//! What a job waits for between its inputs and its first step: building the trainer. Timed
//! with the kernels it compiled ([`SetupTimer`]), and shortened by compiling the trainer's
//! kernels on another thread while the job still makes its masks or loads its scene
//! ([`KernelWarmUp`], issue 38, item 5).

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::training::TrainingStageReport;
use segsplat_engine::train::{TrainConfig, TrainError, Trainer};
use segsplat_gpu::{GpuContext, KernelCompiles};

/// Times building a trainer: wall seconds and the kernels compiled or reused meanwhile.
pub struct SetupTimer {
    started: Instant,
    kernels: KernelCompiles,
    ahead: Option<KernelsCompiledAhead>,
}

/// What building a trainer cost (see [`SetupTimer`]).
#[derive(Debug, Clone, Copy)]
pub struct SetupCost {
    seconds: f64,
    kernels: KernelCompiles,
    ahead: Option<KernelsCompiledAhead>,
}

/// What [`KernelWarmUp`] compiled before the setup, in `metrics.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct KernelsCompiledAhead {
    pub compiled: u64,
    pub seconds: f64,
}

impl SetupTimer {
    /// Starts timing once the warm-up (if any) has finished, so the setup's figures are what
    /// it still had to do itself.
    pub fn start(gpu: &GpuContext, warm_up: Option<KernelWarmUp>) -> Self {
        let ahead = warm_up.and_then(KernelWarmUp::finish);
        Self {
            started: Instant::now(),
            kernels: gpu.kernel_compiles(),
            ahead,
        }
    }

    pub fn finish(self, gpu: &GpuContext) -> SetupCost {
        SetupCost {
            seconds: self.started.elapsed().as_secs_f64(),
            kernels: gpu.kernel_compiles().since(&self.kernels),
            ahead: self.ahead,
        }
    }
}

impl TrainingStageReport {
    /// This report with the trainer's setup filled in.
    pub fn with_setup(self, setup: SetupCost) -> Self {
        Self {
            setup_seconds: setup.seconds,
            setup_kernels_compiled: setup.kernels.compiled,
            setup_kernel_compile_seconds: setup.kernels.compile_seconds,
            setup_kernels_reused: setup.kernels.reused,
            kernels_compiled_ahead: setup.ahead,
            ..self
        }
    }
}

/// The trainer's kernels compiling on their own thread ([`Trainer::compile_kernels`]).
pub struct KernelWarmUp {
    thread: Option<JoinHandle<Result<KernelCompiles, TrainError>>>,
}

impl KernelWarmUp {
    /// Starts compiling the kernels a trainer for `config` will build on `gpu`. A thread that
    /// cannot start only costs the overlap: the trainer compiles what it needs itself.
    pub fn start(gpu: &Arc<GpuContext>, config: &TrainConfig) -> Self {
        let gpu = Arc::clone(gpu);
        let config = config.clone();
        let thread = std::thread::Builder::new()
            .name("kernel-warm-up".to_string())
            .spawn(move || Trainer::compile_kernels(&gpu, &config));
        match thread {
            Ok(thread) => Self {
                thread: Some(thread),
            },
            Err(error) => {
                tracing::warn!(%error, "could not start the kernel warm-up thread");
                Self { thread: None }
            }
        }
    }

    /// Waits for the compiles; what they did, or `None` when they failed (logged: the trainer
    /// then compiles, and reports, what it needs itself).
    pub fn finish(mut self) -> Option<KernelsCompiledAhead> {
        match self.thread.take()?.join() {
            Ok(Ok(compiles)) => Some(KernelsCompiledAhead {
                compiled: compiles.compiled,
                seconds: compiles.compile_seconds,
            }),
            Ok(Err(error)) => {
                tracing::warn!(%error, "compiling the trainer's kernels ahead failed");
                None
            }
            Err(_) => {
                tracing::warn!("the kernel warm-up thread panicked");
                None
            }
        }
    }
}

impl Drop for KernelWarmUp {
    /// A job that fails before its setup still waits for the thread, so no compile outlives
    /// the job on a context that a stopping service releases.
    fn drop(&mut self) {
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
