// 3DGS's opacity reset: every opacity logit above the ceiling (the logit of the reset opacity)
// is lowered to it (`densify::reset_opacity_logits` on the CPU).

@group(0) @binding(0) var<uniform> rules: Rules;
@group(0) @binding(1) var<storage, read_write> opacity_logits: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if i >= rules.count {
        return;
    }
    opacity_logits[i] = min(opacity_logits[i], rules.opacity_ceiling);
}
