//! The optimiser's half of a step: one Adam update per parameter group.

use super::{SMALL_ADAM_GROUPS, TrainError, Trainer};
use crate::adam::{AdamBuffers, AdamGroup};

impl Trainer {
    /// Adam over every parameter group, except SH bands above `sh_degree`: until the degree
    /// ramp reaches a band its gradients are exactly zero, so its moments stay zero and Adam
    /// would leave it unchanged (skipping them saves three quarters of Adam's traffic in the
    /// first thousand steps).
    pub(super) fn encode_adam(
        &self,
        encoder: &mut segsplat_gpu::Encoder,
        step: u32,
        count: u32,
        sh_degree: u32,
    ) -> Result<(), TrainError> {
        let rates = &self.config.learning_rates;
        // Past the laid-out steps every group's rate decays alike (TrainSchedule::polish_factor_at).
        let polish = self.schedule.polish_factor_at(self.step);
        let position_rate = rates.position_at(
            self.step,
            self.schedule.position_decay_steps,
            self.scene_extent,
        ) * polish;
        let [scale_rate, rotation_rate, opacity_rate, sh_dc_rate, rest] = [
            rates.scale,
            rates.rotation,
            rates.opacity,
            rates.sh_dc,
            rates.sh_rest(),
        ]
        .map(|rate| rate * polish);
        let p = &self.gaussians.parameters;
        let g = &self.grads.parameters;
        let m = &self.first_moments;
        let v = &self.second_moments;
        let groups: [(
            &wgpu::Buffer,
            &wgpu::Buffer,
            &wgpu::Buffer,
            &wgpu::Buffer,
            u32,
            f32,
        ); 8] = [
            (&p.means, &g.means, &m.means, &v.means, 3, position_rate),
            (
                &p.log_scales,
                &g.log_scales,
                &m.log_scales,
                &v.log_scales,
                3,
                scale_rate,
            ),
            (
                &p.rotations,
                &g.rotations,
                &m.rotations,
                &v.rotations,
                4,
                rotation_rate,
            ),
            (
                &p.opacity_logits,
                &g.opacity_logits,
                &m.opacity_logits,
                &v.opacity_logits,
                1,
                opacity_rate,
            ),
            (&p.sh_dc, &g.sh_dc, &m.sh_dc, &v.sh_dc, 3, sh_dc_rate),
            (
                &p.sh_rest[0],
                &g.sh_rest[0],
                &m.sh_rest[0],
                &v.sh_rest[0],
                15,
                rest,
            ),
            (
                &p.sh_rest[1],
                &g.sh_rest[1],
                &m.sh_rest[1],
                &v.sh_rest[1],
                15,
                rest,
            ),
            (
                &p.sh_rest[2],
                &g.sh_rest[2],
                &m.sh_rest[2],
                &v.sh_rest[2],
                15,
                rest,
            ),
        ];
        // sh_rest[g] (the last three groups) holds coefficients 1 + 5g ..= 5 + 5g, which start
        // in band g + 1: the first `sh_degree` of them have been reached.
        let reached = groups.len() - 3 + sh_degree.min(3) as usize;
        let steps: Vec<AdamGroup<'_>> = groups
            .into_iter()
            .take(reached)
            .map(
                |(params, grads, first_moment, second_moment, width, rate)| AdamGroup {
                    buffers: AdamBuffers {
                        params,
                        grads,
                        first_moment,
                        second_moment,
                    },
                    element_count: count * width,
                    learning_rate: rate,
                },
            )
            .collect();
        // Where the adapter allows, one dispatch for the groups of 1 to 4 floats per Gaussian and
        // one for the SH rest groups (15 each): a dispatch steps element i of each of its groups
        // together, so its groups should be of similar sizes (adam/groups.rs).
        let (small, rest) = steps.split_at(steps.len().min(SMALL_ADAM_GROUPS));
        self.adam.encode_steps(&self.ctx, encoder, small, step)?;
        self.adam.encode_steps(&self.ctx, encoder, rest, step)?;
        Ok(())
    }
}
