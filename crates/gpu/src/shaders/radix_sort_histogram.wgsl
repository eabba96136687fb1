// Per-block digit histogram of one pass.

@group(0) @binding(0) var<storage, read> sort_info: array<u32>;
@group(0) @binding(1) var<uniform> pass_params: PassParams;
@group(0) @binding(2) var<storage, read> keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> histograms: array<u32>;

var<workgroup> bin_counts: array<atomic<u32>, RADIX_BINS>;

@compute @workgroup_size(SORT_WORKGROUP)
fn radix_histogram(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) workgroups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let count = sort_info[INFO_ELEMENT_COUNT];
    let blocks = sort_info[INFO_BLOCK_COUNT];
    let block = sort_block_index(workgroup, workgroups);
    if block >= blocks {
        return;
    }
    if thread < RADIX_BINS {
        atomicStore(&bin_counts[thread], 0u);
    }
    workgroupBarrier();
    for (var item = 0u; item < SORT_ITEMS_PER_THREAD; item++) {
        let index = block * SORT_BLOCK + item * SORT_WORKGROUP + thread;
        if index < count {
            let digit = (keys[index] >> pass_params.shift) & pass_params.digit_mask;
            atomicAdd(&bin_counts[digit], 1u);
        }
    }
    workgroupBarrier();
    if thread < RADIX_BINS {
        histograms[thread * blocks + block] = atomicLoad(&bin_counts[thread]);
    }
}
