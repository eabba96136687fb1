// A growth bound: in gradient order, a candidate keeps its growth while everything before it
// and itself fit in `max_new` (the CPU's "until the first that does not fit": the prefix sum
// only rises, so every candidate after the first refused is refused too).

@group(0) @binding(0) var<uniform> rules: Rules;
@group(0) @binding(1) var<storage, read_write> flags: array<u32>;
@group(0) @binding(2) var<storage, read> sort_values: array<u32>;
@group(0) @binding(3) var<storage, read> adds: array<u32>;
@group(0) @binding(4) var<storage, read> added_before: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let position = flat_index(gid, groups);
    if position >= rules.count {
        return;
    }
    let i = sort_values[position];
    let flag = flags[i];
    if (flag & GROWTH_MASK) != GROWTH_NONE && added_before[position] + adds[position] > rules.max_new {
        flags[i] = flag & ~GROWTH_MASK;
    }
}
