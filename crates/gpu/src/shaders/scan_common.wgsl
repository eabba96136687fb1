// Shared by the exclusive-scan kernels (scan_blocks.wgsl, scan_add.wgsl).
//
// A scan runs in levels: level 0 scans the input in blocks of SCAN_BLOCK elements and writes each
// block's total to the next level's input; the top level fits in one block; then every level below
// the top adds the scanned block totals back. Element counts per level live in a storage buffer
// (written on the CPU, or on the GPU by a plan kernel when the count is only known there):
// `level_counts[params.counts_index]` is how many inputs this level reads (reads beyond are 0),
// `level_counts[params.counts_index + 1]` how many outputs it writes.

// SCAN_BLOCK is prepended by the host (scan.rs).
const SCAN_WORKGROUP: u32 = 256u;
const SCAN_ITEMS_PER_THREAD: u32 = SCAN_BLOCK / SCAN_WORKGROUP;

struct ScanLevelParams {
    counts_index: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Threads of workgroup_exclusive_sum (workgroup_sum_*.wgsl).
const SUM_THREADS: u32 = SCAN_WORKGROUP;

fn flat_workgroup_index(workgroup: vec3<u32>, workgroups: vec3<u32>) -> u32 {
    return workgroup.x + workgroup.y * workgroups.x;
}
