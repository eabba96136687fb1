// Per position of the candidates sorted by mean gradient: the Gaussians that candidate would
// add (a clone one, a split children - 1, anything else none), for the prefix sum a growth
// bound admits candidates by.

@group(0) @binding(0) var<uniform> rules: Rules;
@group(0) @binding(1) var<storage, read> flags: array<u32>;
@group(0) @binding(2) var<storage, read> sort_values: array<u32>;
@group(0) @binding(3) var<storage, read_write> adds: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let position = flat_index(gid, groups);
    if position >= rules.count {
        return;
    }
    let growth = flags[sort_values[position]] & GROWTH_MASK;
    var added = 0u;
    if growth != GROWTH_NONE {
        added = growth_outputs(growth, rules.children) - 1u;
    }
    adds[position] = added;
}
