//! Stage 1's prompt models, made to notice a stop: a SAM-family model answers a view's point
//! grid in many batches (seconds each on a CPU), so a cancelled job or a stopping service is
//! noticed between batches rather than after the whole stage (issue 39: a job generating masks
//! kept its process running for minutes after SIGTERM).

use tokio_util::sync::CancellationToken;

use crate::jobs::{JobContext, JobFailure};
use segsplat_vision::segment::{
    PointMasks, PointPromptSegmenter, PromptError, RegionAnswer, RegionPrompt,
    RegionPromptSegmenter,
};

/// Why a stage stopped early, as an error: what [`StopAware`] answers once a stop is asked.
#[derive(Debug, thiserror::Error)]
#[error("stopped on request")]
pub struct StopRequested;

/// The job's stop tokens, to check from inside a blocking stage.
#[derive(Clone)]
pub struct StopSignal {
    cancel: CancellationToken,
    shutdown: CancellationToken,
}

impl StopSignal {
    pub fn of(ctx: &JobContext) -> Self {
        Self {
            cancel: ctx.cancel.clone(),
            shutdown: ctx.shutdown.clone(),
        }
    }

    pub fn requested(&self) -> bool {
        self.cancel.is_cancelled() || self.shutdown.is_cancelled()
    }

    fn check(&self) -> Result<(), PromptError> {
        if self.requested() {
            Err(PromptError::Model(Box::new(StopRequested)))
        } else {
            Ok(())
        }
    }
}

/// A prompt model that refuses work once the job is asked to stop.
pub struct StopAware<S> {
    inner: S,
    stop: StopSignal,
}

impl<S> StopAware<S> {
    pub fn new(inner: S, stop: StopSignal) -> Self {
        Self { inner, stop }
    }
}

impl<S: PointPromptSegmenter> PointPromptSegmenter for StopAware<S> {
    fn set_image(&mut self, image: &image::RgbImage) -> Result<(), PromptError> {
        self.stop.check()?;
        self.inner.set_image(image)
    }

    fn predict_points(&mut self, points: &[[f32; 2]]) -> Result<Vec<PointMasks>, PromptError> {
        self.stop.check()?;
        self.inner.predict_points(points)
    }
}

impl<S: RegionPromptSegmenter> RegionPromptSegmenter for StopAware<S> {
    fn set_image(&mut self, image: &image::RgbImage) -> Result<(), PromptError> {
        self.stop.check()?;
        self.inner.set_image(image)
    }

    fn predict_regions(
        &mut self,
        prompts: &[RegionPrompt],
    ) -> Result<Vec<RegionAnswer>, PromptError> {
        self.stop.check()?;
        self.inner.predict_regions(prompts)
    }
}

/// A stage's error as the job's failure: the stop itself when one was asked (the error is then
/// the stop showing through the stage), else `otherwise(error)`.
pub fn stop_or(
    ctx: &JobContext,
    error: impl std::fmt::Display,
    otherwise: fn(String) -> JobFailure,
) -> JobFailure {
    match ctx.stop_requested() {
        Err(stop) => stop,
        Ok(()) => otherwise(error.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Counting(usize);

    impl PointPromptSegmenter for Counting {
        fn set_image(&mut self, _: &image::RgbImage) -> Result<(), PromptError> {
            Ok(())
        }

        fn predict_points(&mut self, points: &[[f32; 2]]) -> Result<Vec<PointMasks>, PromptError> {
            self.0 += points.len();
            Ok(Vec::new())
        }
    }

    #[test]
    fn a_stop_refuses_the_next_batch() {
        let cancel = CancellationToken::new();
        let stop = StopSignal {
            cancel: cancel.clone(),
            shutdown: CancellationToken::new(),
        };
        let mut model = StopAware::new(Counting(0), stop);
        model.predict_points(&[[0.0, 0.0]; 4]).unwrap();
        cancel.cancel();
        let refused = model.predict_points(&[[0.0, 0.0]; 4]).unwrap_err();
        assert!(
            refused.to_string().contains("stopped on request"),
            "{refused}"
        );
        assert_eq!(model.inner.0, 4);
    }
}
