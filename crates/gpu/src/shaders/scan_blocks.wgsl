// Exclusive scan of one level, block by block; each block's total goes to `block_totals`.
// Thread t of a block owns the SCAN_ITEMS_PER_THREAD consecutive elements from t * 4.

@group(0) @binding(0) var<storage, read> level_counts: array<u32>;
@group(0) @binding(1) var<uniform> params: ScanLevelParams;
@group(0) @binding(2) var<storage, read> input: array<u32>;
@group(0) @binding(3) var<storage, read_write> output: array<u32>;
@group(0) @binding(4) var<storage, read_write> block_totals: array<u32>;

@compute @workgroup_size(SCAN_WORKGROUP)
fn scan_blocks(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let input_count = level_counts[params.counts_index];
    let output_count = level_counts[params.counts_index + 1u];
    let block = flat_workgroup_index(workgroup, workgroups);
    if block * SCAN_BLOCK >= output_count {
        return;
    }
    let first = block * SCAN_BLOCK + thread * SCAN_ITEMS_PER_THREAD;
    var exclusive_in_thread: array<u32, SCAN_ITEMS_PER_THREAD>;
    var thread_total = 0u;
    for (var item = 0u; item < SCAN_ITEMS_PER_THREAD; item++) {
        let index = first + item;
        exclusive_in_thread[item] = thread_total;
        if index < input_count {
            thread_total += input[index];
        }
    }
    let thread_offset = workgroup_exclusive_sum(thread, thread_total);
    for (var item = 0u; item < SCAN_ITEMS_PER_THREAD; item++) {
        let index = first + item;
        if index < output_count {
            output[index] = thread_offset + exclusive_in_thread[item];
        }
    }
    if thread == SCAN_WORKGROUP - 1u {
        block_totals[block] = thread_offset + thread_total;
    }
}
