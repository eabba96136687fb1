// Copies the first `count` sorted pairs from the scratch buffers back to the caller's buffers
// (after an odd number of passes), leaving elements beyond `count` untouched.

const COPY_WORKGROUP: u32 = 256u;

@group(0) @binding(0) var<storage, read> sort_info: array<u32>;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> values_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> values_out: array<u32>;

@compute @workgroup_size(COPY_WORKGROUP)
fn copy_sorted(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let index = (workgroup.x + workgroup.y * workgroups.x) * COPY_WORKGROUP + thread;
    if index < sort_info[INFO_ELEMENT_COUNT] {
        keys_out[index] = keys_in[index];
        values_out[index] = values_in[index];
    }
}
