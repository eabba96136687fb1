// destination[offset + i] += sum over splits s (in order) of partials[s * count + i]: the deterministic
// second half of a split-K weight or bias gradient. Accumulates, so chunks of Gaussians add up.

struct ReduceParams {
    count: u32,
    splits: u32,
    target_offset: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: ReduceParams;
@group(0) @binding(1) var<storage, read> partials: array<f32>;
@group(0) @binding(2) var<storage, read_write> destination: array<f32>;

@compute @workgroup_size(256, 1, 1)
fn split_reduce(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let i = (group.x + group.y * groups.x) * 256u + thread;
    if i >= params.count {
        return;
    }
    var sum = 0.0;
    for (var s = 0u; s < params.splits; s++) {
        sum += partials[s * params.count + i];
    }
    destination[params.target_offset + i] += sum;
}
