//! A CPU-only job kind for exercising the queue: counts steps with progress, checkpoints after
//! each step (so a resumed attempt continues; a blob-store outage is `JobFailure::Unavailable`),
//! honours cancel and shutdown between steps, and can fail its first attempts on request.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use futures::future::BoxFuture;
use segsplat_service::jobs::{JobContext, JobFailure, JobHandler, Progress};
use serde::{Deserialize, Serialize};

pub const STEPS_KIND: &str = "test_steps";

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StepsConfig {
    pub steps: u64,
    pub step_ms: u64,
    /// Attempts up to this number fail with a retryable error before doing any step.
    pub fail_attempts: u32,
}

impl Default for StepsConfig {
    fn default() -> Self {
        Self {
            steps: 3,
            step_ms: 10,
            fail_attempts: 0,
        }
    }
}

/// What the handler did, for assertions.
#[derive(Debug, Default)]
pub struct StepsStats {
    pub runs: AtomicU64,
    pub steps_executed: AtomicU64,
}

#[derive(Debug, Default, Clone)]
pub struct StepsHandler {
    pub stats: Arc<StepsStats>,
}

impl StepsHandler {
    pub fn new() -> Self {
        Self::default()
    }
}

impl JobHandler for StepsHandler {
    fn kind(&self) -> &'static str {
        STEPS_KIND
    }

    fn needs_gpu(&self) -> bool {
        false
    }

    fn validate_config(&self, config: &serde_json::Value) -> Result<serde_json::Value, String> {
        let config = if config.is_null() {
            serde_json::json!({})
        } else {
            config.clone()
        };
        let parsed: StepsConfig =
            serde_json::from_value(config).map_err(|error| error.to_string())?;
        if parsed.steps == 0 {
            return Err("steps: must be >= 1".to_string());
        }
        serde_json::to_value(parsed).map_err(|error| error.to_string())
    }

    fn run(&self, ctx: JobContext) -> BoxFuture<'static, Result<(), JobFailure>> {
        let stats = self.stats.clone();
        Box::pin(async move {
            stats.runs.fetch_add(1, Ordering::SeqCst);
            let config: StepsConfig = serde_json::from_value(ctx.config.clone())
                .map_err(|error| JobFailure::Fatal(error.to_string()))?;
            if ctx.attempt <= config.fail_attempts {
                return Err(JobFailure::Retryable(format!(
                    "simulated failure on attempt {}",
                    ctx.attempt
                )));
            }
            assert!(
                ctx.scene_dir.join("sparse").is_dir(),
                "scene files are reachable"
            );
            let decode_step = |bytes: &[u8]| {
                <[u8; 8]>::try_from(bytes)
                    .map(u64::from_le_bytes)
                    .map_err(|_| format!("{} bytes, not 8", bytes.len()))
            };
            let resume_from = match ctx.load_checkpoint("step", decode_step) {
                Ok(Some(step)) => step,
                Ok(None) => 0,
                Err(error) => return Err(JobFailure::from(error)),
            };
            for step in resume_from..config.steps {
                ctx.stop_requested()?;
                tokio::time::sleep(Duration::from_millis(config.step_ms)).await;
                stats.steps_executed.fetch_add(1, Ordering::SeqCst);
                ctx.save_checkpoint("step", &(step + 1).to_le_bytes())?;
                let mut progress = Progress {
                    stage: "count".to_string(),
                    step: step + 1,
                    total_steps: config.steps,
                    ..Progress::default()
                };
                progress
                    .metrics
                    .insert("loss".to_string(), 1.0 / (step + 1) as f64);
                // As the real job kinds do (`job_kinds::training::report`): a report the
                // database cannot take (an outage) is logged, and the work goes on.
                if let Err(error) = ctx.progress.report(progress).await {
                    eprintln!("progress report failed: {error}");
                }
            }
            Ok(())
        })
    }
}
