// Adds each block's scanned offset (from the level above) to the block's outputs.

@group(0) @binding(0) var<storage, read> level_counts: array<u32>;
@group(0) @binding(1) var<uniform> params: ScanLevelParams;
@group(0) @binding(2) var<storage, read_write> output: array<u32>;
@group(0) @binding(3) var<storage, read> block_offsets: array<u32>;

@compute @workgroup_size(SCAN_WORKGROUP)
fn add_block_offsets(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let output_count = level_counts[params.counts_index + 1u];
    let block = flat_workgroup_index(workgroup, workgroups);
    // Block 0's offset is 0 by construction.
    if block == 0u || block * SCAN_BLOCK >= output_count {
        return;
    }
    let offset = block_offsets[block];
    for (var item = 0u; item < SCAN_ITEMS_PER_THREAD; item++) {
        let index = block * SCAN_BLOCK + item * SCAN_WORKGROUP + thread;
        if index < output_count {
            output[index] += offset;
        }
    }
}
