// Per surviving Gaussian: writes where each of its outputs comes from, at its place from the
// scan: the row itself (kind 0), then its clone (kind 1); or its split children (kind 2 + child).
// The order is the CPU plan's: survivors in index order, each followed by its additions.

@group(0) @binding(0) var<uniform> rules: Rules;
@group(0) @binding(1) var<storage, read> flags: array<u32>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> origin_source: array<u32>;
@group(0) @binding(4) var<storage, read_write> origin_kind: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if i >= rules.count {
        return;
    }
    let first = offsets[i];
    let outputs = offsets[i + 1u] - first;
    let split = (flags[i] & GROWTH_MASK) == GROWTH_SPLIT;
    for (var k = 0u; k < outputs; k++) {
        origin_source[first + k] = i;
        origin_kind[first + k] = select(k, 2u + k, split);
    }
}
