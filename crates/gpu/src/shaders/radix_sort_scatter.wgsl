// Stable scatter of one pass: each element goes to
//   bin_offsets[digit * blocks + block]            (scanned histograms: elements before this block's)
//   + rank of the element among its block's elements with the same digit.
// The rank comes from a bin-major table of per-thread digit counts, scanned in shared memory:
// after the scan, entry (bin, thread) counts the block's elements with a smaller digit, plus those
// with this digit owned by earlier threads.

@group(0) @binding(0) var<storage, read> sort_info: array<u32>;
@group(0) @binding(1) var<uniform> pass_params: PassParams;
@group(0) @binding(2) var<storage, read> keys_in: array<u32>;
@group(0) @binding(3) var<storage, read> values_in: array<u32>;
@group(0) @binding(4) var<storage, read> bin_offsets: array<u32>;
@group(0) @binding(5) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(6) var<storage, read_write> values_out: array<u32>;

const NO_DIGIT: u32 = 0xffffffffu;
// The table has RADIX_BINS * SORT_WORKGROUP entries, scanned in runs of RADIX_BINS per thread.
const TABLE_ENTRIES_PER_THREAD: u32 = RADIX_BINS;

var<workgroup> bin_thread_table: array<u32, RADIX_BINS * SORT_WORKGROUP>;
@compute @workgroup_size(SORT_WORKGROUP)
fn radix_scatter(
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
    let first = block * SORT_BLOCK + thread * SORT_ITEMS_PER_THREAD;
    var keys: array<u32, SORT_ITEMS_PER_THREAD>;
    var values: array<u32, SORT_ITEMS_PER_THREAD>;
    var digits: array<u32, SORT_ITEMS_PER_THREAD>;
    for (var item = 0u; item < SORT_ITEMS_PER_THREAD; item++) {
        let index = first + item;
        if index < count {
            keys[item] = keys_in[index];
            values[item] = values_in[index];
            digits[item] = (keys[item] >> pass_params.shift) & pass_params.digit_mask;
        } else {
            digits[item] = NO_DIGIT;
        }
    }

    // This thread's count of each digit, into column `thread` of the bin-major table.
    for (var bin = 0u; bin < RADIX_BINS; bin++) {
        var bin_count = 0u;
        for (var item = 0u; item < SORT_ITEMS_PER_THREAD; item++) {
            bin_count += select(0u, 1u, digits[item] == bin);
        }
        bin_thread_table[bin * SORT_WORKGROUP + thread] = bin_count;
    }
    workgroupBarrier();

    // Exclusive scan of the whole table: each thread scans a run of consecutive entries, then the
    // runs' totals are scanned across threads.
    let run_start = thread * TABLE_ENTRIES_PER_THREAD;
    var run_total = 0u;
    for (var entry = 0u; entry < TABLE_ENTRIES_PER_THREAD; entry++) {
        let entry_count = bin_thread_table[run_start + entry];
        bin_thread_table[run_start + entry] = run_total;
        run_total += entry_count;
    }
    let run_offset = workgroup_exclusive_sum(thread, run_total);
    for (var entry = 0u; entry < TABLE_ENTRIES_PER_THREAD; entry++) {
        bin_thread_table[run_start + entry] += run_offset;
    }
    workgroupBarrier();

    for (var item = 0u; item < SORT_ITEMS_PER_THREAD; item++) {
        let digit = digits[item];
        if digit == NO_DIGIT {
            continue;
        }
        var rank = bin_thread_table[digit * SORT_WORKGROUP + thread] - bin_thread_table[digit * SORT_WORKGROUP];
        for (var earlier = 0u; earlier < item; earlier++) {
            rank += select(0u, 1u, digits[earlier] == digit);
        }
        let destination = bin_offsets[digit * blocks + block] + rank;
        keys_out[destination] = keys[item];
        values_out[destination] = values[item];
    }
}
