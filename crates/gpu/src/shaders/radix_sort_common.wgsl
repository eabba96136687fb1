// Shared by the radix-sort kernels (radix_sort_*.wgsl).
//
// LSD radix sort, RADIX_BITS bits a pass. Elements are processed in blocks of SORT_BLOCK; thread t
// of a block owns the SORT_ITEMS_PER_THREAD consecutive elements from t * SORT_ITEMS_PER_THREAD, so
// (thread, item) order is the input order, which the scatter keeps (stability).
//
// `sort_info` is written on the GPU by radix_sort_plan.wgsl from the element count:
// [0] element count, [1] block count, then the histogram scan's level counts (scan_common.wgsl).
// Histograms are bin-major, `histograms[bin * block_count + block]`, so their exclusive scan is,
// for each (bin, block), where that block's elements of that bin go.

// RADIX_BITS and SORT_BLOCK are prepended by the host (gpu/sort.rs).
const RADIX_BINS: u32 = 1u << RADIX_BITS;
const SORT_WORKGROUP: u32 = 128u;
const SORT_ITEMS_PER_THREAD: u32 = SORT_BLOCK / SORT_WORKGROUP;
// Threads of workgroup_exclusive_sum (workgroup_sum_*.wgsl), used by the scatter.
const SUM_THREADS: u32 = SORT_WORKGROUP;

const INFO_ELEMENT_COUNT: u32 = 0u;
const INFO_BLOCK_COUNT: u32 = 1u;

struct PassParams {
    // Lowest key bit of this pass' digit.
    shift: u32,
    // Digit mask: RADIX_BINS - 1, or fewer bits in a last pass beyond `key_bits`.
    digit_mask: u32,
    _pad0: u32,
    _pad1: u32,
}

fn sort_block_index(workgroup: vec3<u32>, workgroups: vec3<u32>) -> u32 {
    return workgroup.x + workgroup.y * workgroups.x;
}
