// Sums each slot's per-invocation loss partials (loss_per_pixel.wgsl) in a fixed order
// (deterministic) and writes weight * sum / N to `loss_values[first_loss_slot + slot]`. One
// workgroup per slot.

@group(0) @binding(1) var<storage, read> loss_partials: array<f32>;
@group(0) @binding(2) var<storage, read_write> loss_values: array<f32>;

var<workgroup> thread_sums: array<f32, 256>;

@compute @workgroup_size(256)
fn reduce_loss(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    slot = workgroup.x;
    let first = slot * params.partial_count;
    var sum = 0.0;
    for (var index = thread; index < params.partial_count; index += 256u) {
        sum += loss_partials[first + index];
    }
    thread_sums[thread] = sum;
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride = stride >> 1u) {
        if thread < stride {
            thread_sums[thread] += thread_sums[thread + stride];
        }
        workgroupBarrier();
    }
    if thread == 0u {
        loss_values[params.first_loss_slot + slot] =
            params.weight * params.inv_value_count * thread_sums[0];
    }
}
