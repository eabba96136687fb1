//! How the deformation field trains: its shape, the warm-up, its learning-rate schedule and the
//! annealed time noise (Deformable 3DGS's constants, docs/method.md "Dynamic scenes").

use serde::{Deserialize, Serialize};

use super::field::FieldShape;
use crate::schedule::exponential_decay;
use crate::train::schedule::DeformationSchedule;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DeformationConfig {
    /// The field's shape. Left out (`None`), the trainer gives it the shape for its adapter
    /// ([`FieldShape::for_adapter`]) when it starts, so its `config()` and checkpoints name the
    /// shape that trained.
    pub field: Option<FieldShape>,
    /// Steps trained as a static scene before the field starts moving Gaussians. This and the
    /// other step counts left out (`None`) are Deformable 3DGS's values for a 30k-step job
    /// (3000, 40000, 20000) scaled to the job's `steps` (`splat::train::schedule`).
    pub warm_up_steps: Option<u32>,
    /// Adam learning rate of the field, decayed log-linearly to `learning_rate_final` over
    /// `learning_rate_decay_steps` counted from step 0 (the released code: position_lr_init x 5
    /// to position_lr_final over 40k steps).
    pub learning_rate_initial: f32,
    pub learning_rate_final: f32,
    pub learning_rate_decay_steps: Option<u32>,
    /// Gaussian noise added to each step's time, `N(0, 1) * interval * scale * (1 - step /
    /// time_noise_steps)` where `interval` is the gap between distinct training times: keeps the
    /// field smooth between frames early on. 0 disables it.
    pub time_noise_scale: f32,
    pub time_noise_steps: Option<u32>,
    /// Gaussians whose activations are held at once (memory bound of the field's passes).
    pub chunk_gaussians: usize,
}

impl Default for DeformationConfig {
    fn default() -> Self {
        Self {
            field: None,
            warm_up_steps: None,
            learning_rate_initial: 0.0008,
            learning_rate_final: 1.6e-6,
            learning_rate_decay_steps: None,
            time_noise_scale: 0.1,
            time_noise_steps: None,
            chunk_gaussians: 65_536,
        }
    }
}

impl DeformationConfig {
    /// The shape that trains: the given one, or the one for the adapter (`software`: a CPU
    /// adapter) when the config leaves it out.
    pub fn field_for(&self, software: bool) -> FieldShape {
        self.field
            .unwrap_or_else(|| FieldShape::for_adapter(software))
    }

    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if let Some(field) = &self.field {
            field
                .validate()
                .map_err(|problem| ("deformation.field", problem))?;
        }
        if !(self.learning_rate_initial > 0.0 && self.learning_rate_final > 0.0) {
            return Err((
                "deformation.learning_rate_initial",
                "learning rates must be positive".into(),
            ));
        }
        if !(0.0..=10.0).contains(&self.time_noise_scale) {
            return Err((
                "deformation.time_noise_scale",
                "must be within 0..=10".into(),
            ));
        }
        if self.chunk_gaussians == 0 {
            return Err(("deformation.chunk_gaussians", "must be at least 1".into()));
        }
        Ok(())
    }

    /// The field's learning rate at `step`, decaying over `schedule`'s steps.
    pub fn learning_rate_at(&self, step: u32, schedule: &DeformationSchedule) -> f32 {
        exponential_decay(
            self.learning_rate_initial,
            self.learning_rate_final,
            step,
            schedule.learning_rate_decay_steps,
        )
    }

    /// Standard deviation of the time noise at `step`, for training times `interval` apart.
    pub fn time_noise_at(&self, step: u32, interval: f32, schedule: &DeformationSchedule) -> f32 {
        if schedule.time_noise_steps == 0 {
            return 0.0;
        }
        let remaining = 1.0 - (step as f32 / schedule.time_noise_steps as f32).min(1.0);
        interval * self.time_noise_scale * remaining
    }
}

/// The gap between consecutive distinct times (1 when there is at most one).
pub fn time_interval(times: impl IntoIterator<Item = f32>) -> f32 {
    let mut sorted: Vec<f32> = times.into_iter().filter(|t| t.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    sorted.dedup();
    if sorted.len() < 2 {
        return 1.0;
    }
    (sorted[sorted.len() - 1] - sorted[0]) / (sorted.len() - 1) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedules_follow_the_released_constants() {
        let config = DeformationConfig::default();
        // At 30k steps the defaults are the released ones.
        let schedule = DeformationSchedule::resolve(&config, 30_000);
        assert!(!schedule.active_at(2999) && schedule.active_at(3000));
        assert!((config.learning_rate_at(0, &schedule) - 0.0008).abs() < 1e-9);
        assert!((config.learning_rate_at(40_000, &schedule) - 1.6e-6).abs() < 1e-10);
        assert!((config.time_noise_at(0, 0.01, &schedule) - 0.001).abs() < 1e-9);
        assert_eq!(config.time_noise_at(20_000, 0.01, &schedule), 0.0);
        assert!((time_interval([0.0, 0.5, 1.0, 0.5]) - 0.5).abs() < 1e-6);
        assert_eq!(time_interval([0.3]), 1.0);
    }

    #[test]
    fn the_fields_shape_follows_the_adapter_unless_given() {
        let released = FieldShape::default();
        let narrow = FieldShape::for_adapter(true);
        assert_eq!(FieldShape::for_adapter(false), released);
        let flops = |shape: FieldShape| {
            let (forward, backward) = shape.flops_per_gaussian();
            forward + backward
        };
        assert!(flops(narrow) * 10 < flops(released));
        assert!(narrow.validate().is_ok());
        let parse = |json: serde_json::Value| -> DeformationConfig {
            serde_json::from_value(json).expect("a deformation config")
        };
        // Left out, or only the field left out: the adapter's shape.
        let left_out = parse(serde_json::json!({"warm_up_steps": 10}));
        assert_eq!(left_out.field_for(true), narrow);
        assert_eq!(left_out.field_for(false), released);
        // A given field is kept on any adapter, its own left-out keys at the released values.
        let given = parse(serde_json::json!({"field": {"width": 32}}));
        let width_32 = FieldShape {
            width: 32,
            ..released
        };
        assert_eq!(given.field_for(true), width_32);
        assert_eq!(given.field_for(false), width_32);
        // A bad given shape is named; a left-out one is never checked against a default.
        let too_deep = parse(serde_json::json!({"field": {"depth": 40}}));
        assert_eq!(
            too_deep.validate().map_err(|(key, _)| key),
            Err("deformation.field")
        );
        assert!(left_out.validate().is_ok());
    }
}
