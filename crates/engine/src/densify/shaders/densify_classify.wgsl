// Per Gaussian: does it grow (clone when small, split when large) and is it a pruning
// candidate, compared exactly as `DensifyThresholds::classify` does on the CPU. Also writes the
// sort keys a growth bound ranks candidates by: the bitwise complement of the mean gradient
// (positive floats order as their bits, so ascending keys are descending gradients; the stable
// sort breaks ties by index), and the largest key for everything else.

@group(0) @binding(0) var<uniform> rules: Rules;
@group(0) @binding(1) var<storage, read> log_scales: array<f32>;
@group(0) @binding(2) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(3) var<storage, read> gradient_sums: array<f32>;
@group(0) @binding(4) var<storage, read> visible_counts: array<u32>;
@group(0) @binding(5) var<storage, read> max_radii: array<f32>;
@group(0) @binding(6) var<storage, read_write> flags: array<u32>;
@group(0) @binding(7) var<storage, read_write> sort_keys: array<u32>;
@group(0) @binding(8) var<storage, read_write> sort_values: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if i >= rules.count {
        return;
    }
    let max_log_scale = max(max(log_scales[3u * i], log_scales[3u * i + 1u]), log_scales[3u * i + 2u]);
    let visible = visible_counts[i];
    let gradient_sum = gradient_sums[i];
    var growth = GROWTH_NONE;
    if gradient_sum >= rules.gradient * f32(visible) {
        growth = select(GROWTH_SPLIT, GROWTH_CLONE, max_log_scale <= rules.log_dense_limit);
    }
    let prune = opacity_logits[i] < rules.min_opacity_logit
        || max_radii[i] > rules.screen_radius
        || max_log_scale > rules.log_world_scale;
    // A pruning candidate does not grow (`DensifyThresholds::classify`).
    if prune {
        growth = GROWTH_NONE;
    }
    flags[i] = growth | select(0u, PRUNE_BIT, prune);
    var key = 0xffffffffu;
    if growth != GROWTH_NONE {
        key = ~bitcast<u32>(gradient_sum / f32(max(visible, 1u)));
    }
    sort_keys[i] = key;
    sort_values[i] = i;
}
