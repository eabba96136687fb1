//! Learning rates and their schedules, as the original 3DGS code sets them.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Per-parameter-group learning rates (3DGS defaults; position rates are multiplied by the scene
/// extent, so they are scale-free).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LearningRates {
    pub position_initial: f32,
    pub position_final: f32,
    /// Steps over which the position rate decays exponentially from initial to final; left
    /// out: the job's `steps` (3DGS: 30k for a 30k-step job).
    pub position_decay_steps: Option<u32>,
    pub sh_dc: f32,
    /// Higher SH bands learn `sh_rest_divisor` times slower than the DC term.
    pub sh_rest_divisor: f32,
    pub opacity: f32,
    pub scale: f32,
    pub rotation: f32,
}

impl Default for LearningRates {
    fn default() -> Self {
        Self {
            position_initial: 1.6e-4,
            position_final: 1.6e-6,
            position_decay_steps: None,
            sh_dc: 2.5e-3,
            sh_rest_divisor: 20.0,
            opacity: 0.05,
            scale: 5e-3,
            rotation: 1e-3,
        }
    }
}

impl LearningRates {
    /// Position learning rate at `step`: log-linear interpolation from initial to final over
    /// `decay_steps` (the resolved `position_decay_steps`), times the scene extent.
    pub fn position_at(&self, step: u32, decay_steps: u32, scene_extent: f32) -> f32 {
        exponential_decay(
            self.position_initial,
            self.position_final,
            step,
            decay_steps,
        ) * scene_extent
    }

    pub fn sh_rest(&self) -> f32 {
        self.sh_dc / self.sh_rest_divisor
    }
}

/// `initial^(1-t) * final^t` with `t = step / steps` clamped to [0, 1].
pub fn exponential_decay(initial: f32, final_value: f32, step: u32, steps: u32) -> f32 {
    if initial <= 0.0 || final_value <= 0.0 {
        return 0.0;
    }
    let t = (step as f64 / steps.max(1) as f64).clamp(0.0, 1.0);
    ((initial as f64).ln() * (1.0 - t) + (final_value as f64).ln() * t).exp() as f32
}

/// 3DGS's "cameras extent": 1.1 x the largest distance from the mean camera centre to any camera
/// centre. Position learning rates and densification size thresholds scale with it. Falls back to
/// 1 for a single camera (or cameras at one point) so nothing becomes zero.
pub fn scene_extent(camera_centers: &[Vec3]) -> f32 {
    if camera_centers.is_empty() {
        return 1.0;
    }
    let center = camera_centers.iter().copied().sum::<Vec3>() / camera_centers.len() as f32;
    let radius = camera_centers
        .iter()
        .map(|c| c.distance(center))
        .fold(0.0f32, f32::max);
    if radius > 0.0 { radius * 1.1 } else { 1.0 }
}

/// Active SH degree at `step`: one more band every `steps_per_degree` steps, up to `max_degree`.
pub fn sh_degree_at(step: u32, steps_per_degree: u32, max_degree: u32) -> u32 {
    (step / steps_per_degree.max(1)).min(max_degree)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decay_hits_both_ends_and_is_log_linear() {
        assert!((exponential_decay(1e-2, 1e-4, 0, 100) - 1e-2).abs() < 1e-9);
        assert!((exponential_decay(1e-2, 1e-4, 100, 100) - 1e-4).abs() < 1e-9);
        assert!((exponential_decay(1e-2, 1e-4, 50, 100) - 1e-3).abs() < 1e-8);
        assert!((exponential_decay(1e-2, 1e-4, 500, 100) - 1e-4).abs() < 1e-9);
    }

    #[test]
    fn position_rate_scales_with_extent() {
        let rates = LearningRates::default();
        let small = rates.position_at(0, 30_000, 1.0);
        let large = rates.position_at(0, 30_000, 10.0);
        assert!((large / small - 10.0).abs() < 1e-4);
    }

    #[test]
    fn extent_of_a_camera_ring() {
        let ring: Vec<Vec3> = (0..8)
            .map(|i| {
                let a = i as f32 / 8.0 * std::f32::consts::TAU;
                Vec3::new(2.0 * a.cos(), 2.0 * a.sin(), 1.0)
            })
            .collect();
        assert!((scene_extent(&ring) - 2.2).abs() < 1e-5);
        assert_eq!(scene_extent(&[Vec3::ONE]), 1.0);
    }

    #[test]
    fn sh_degree_ramps() {
        assert_eq!(sh_degree_at(0, 1000, 3), 0);
        assert_eq!(sh_degree_at(1999, 1000, 3), 1);
        assert_eq!(sh_degree_at(99_000, 1000, 3), 3);
    }
}
