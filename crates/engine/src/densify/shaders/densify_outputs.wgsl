// Per Gaussian: how many Gaussians it becomes (0 when pruned), for the scan that places every
// output; and the plan's totals (cloned, split, pruned) for the log.

@group(0) @binding(0) var<uniform> rules: Rules;
@group(0) @binding(1) var<storage, read> flags: array<u32>;
@group(0) @binding(2) var<storage, read_write> output_counts: array<u32>;
// [new count (copied in after the scan), cloned, split, pruned]
@group(0) @binding(3) var<storage, read_write> summary: array<atomic<u32>, 4>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if i >= rules.count {
        return;
    }
    let flag = flags[i];
    let growth = flag & GROWTH_MASK;
    if (flag & PRUNE_BIT) != 0u {
        output_counts[i] = 0u;
        atomicAdd(&summary[3], 1u);
        return;
    }
    output_counts[i] = growth_outputs(growth, rules.children);
    if growth == GROWTH_CLONE {
        atomicAdd(&summary[1], 1u);
    } else if growth == GROWTH_SPLIT {
        atomicAdd(&summary[2], 1u);
    }
}
