// One thread: reads the element count written by an earlier kernel, clamps it to the capacity and
// derives every count and indirect dispatch size the sort passes need, so the CPU never reads it.
//
// dispatch_args (three u32 each): [0] one group per sort block, [1] one group per
// COPY_WORKGROUP elements, [2 + level] the histogram scan's level `level`.

const MAX_GROUPS_PER_DIMENSION: u32 = 65535u;
const COPY_WORKGROUP: u32 = 256u;
// SCAN_BLOCK is prepended by the host (gpu/scan.rs).
const FIRST_LEVEL_COUNTS_INDEX: u32 = 2u;

struct PlanParams {
    // Index of the count (a u32) in `count_source`.
    count_index: u32,
    capacity: u32,
    scan_levels: u32,
    _pad: u32,
}

@group(0) @binding(0) var<storage, read> count_source: array<u32>;
@group(0) @binding(1) var<uniform> params: PlanParams;
@group(0) @binding(2) var<storage, read_write> sort_info: array<u32>;
@group(0) @binding(3) var<storage, read_write> dispatch_args: array<u32>;

fn write_groups(slot: u32, groups: u32) {
    let x = min(groups, MAX_GROUPS_PER_DIMENSION);
    let y = (groups + MAX_GROUPS_PER_DIMENSION - 1u) / MAX_GROUPS_PER_DIMENSION;
    dispatch_args[slot * 3u] = x;
    dispatch_args[slot * 3u + 1u] = y;
    dispatch_args[slot * 3u + 2u] = 1u;
}

@compute @workgroup_size(1)
fn plan_sort() {
    let count = min(count_source[params.count_index], params.capacity);
    let blocks = (count + SORT_BLOCK - 1u) / SORT_BLOCK;
    sort_info[INFO_ELEMENT_COUNT] = count;
    sort_info[INFO_BLOCK_COUNT] = blocks;
    write_groups(0u, blocks);
    write_groups(1u, (count + COPY_WORKGROUP - 1u) / COPY_WORKGROUP);

    // The scatter reads no total, so the histogram scan writes none: 1024 histograms (64 blocks)
    // need one level (level_output_counts_without_total in scan.rs).
    let histogram_count = blocks * RADIX_BINS;
    var output_count = histogram_count;
    for (var level = 0u; level < params.scan_levels; level++) {
        let counts_index = FIRST_LEVEL_COUNTS_INDEX + 2u * level;
        if level == 0u {
            sort_info[counts_index] = histogram_count;
        } else {
            output_count = (output_count + SCAN_BLOCK - 1u) / SCAN_BLOCK;
            sort_info[counts_index] = output_count;
        }
        sort_info[counts_index + 1u] = output_count;
        write_groups(2u + level, (output_count + SCAN_BLOCK - 1u) / SCAN_BLOCK);
    }
}
