// The whole radix sort in one workgroup, for element counts small enough that the multi-block
// sort's ~3 dispatches a pass cost more than the sorting (a small scene's depth sort: 8 passes,
// 25 dispatches, against this one). Same contract as the multi-block sort: a stable ascending
// sort by the low `key_bits` bits, the count read on the GPU and clamped to the capacity,
// elements from the count on untouched, the result in the caller's buffers.
//
// Thread t owns the contiguous segment [t * per_thread, (t + 1) * per_thread) of the input, so a
// pass needs no ranking inside the workgroup: each thread counts its segment's digits, one
// exclusive sum over (digit, thread) gives every thread its first slot per digit, and each thread
// then writes its segment in order, which keeps the sort stable. Three barriers a pass.

const SMALL_SORT_THREADS: u32 = 64u;
const SMALL_RADIX_BITS: u32 = 4u;
const SMALL_RADIX_BINS: u32 = 16u;
// SMALL_RADIX_BINS x SMALL_SORT_THREADS, digit-major: offsets[digit * threads + thread].
const SMALL_OFFSETS: u32 = 1024u;
// Consecutive offsets each thread sums in the exclusive scan (SMALL_OFFSETS / threads).
const SMALL_SCAN_RUN: u32 = 16u;

struct SmallSortParams {
    // Index of the count (a u32) in `count_source`.
    count_index: u32,
    capacity: u32,
    key_bits: u32,
    _pad: u32,
}

@group(0) @binding(0) var<storage, read> count_source: array<u32>;
@group(0) @binding(1) var<uniform> params: SmallSortParams;
@group(0) @binding(2) var<storage, read_write> keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> values: array<u32>;
@group(0) @binding(4) var<storage, read_write> scratch_keys: array<u32>;
@group(0) @binding(5) var<storage, read_write> scratch_values: array<u32>;

var<workgroup> offsets: array<u32, SMALL_OFFSETS>;
var<workgroup> run_totals: array<u32, SMALL_SORT_THREADS>;

fn pass_key(index: u32, from_caller: bool) -> u32 {
    if from_caller {
        return keys[index];
    }
    return scratch_keys[index];
}

fn pass_value(index: u32, from_caller: bool) -> u32 {
    if from_caller {
        return values[index];
    }
    return scratch_values[index];
}

fn write_pair(index: u32, key: u32, value: u32, to_caller: bool) {
    if to_caller {
        keys[index] = key;
        values[index] = value;
    } else {
        scratch_keys[index] = key;
        scratch_values[index] = value;
    }
}

@compute @workgroup_size(64)
fn small_sort(@builtin(local_invocation_index) thread: u32) {
    let count = min(count_source[params.count_index], params.capacity);
    let per_thread = (count + SMALL_SORT_THREADS - 1u) / SMALL_SORT_THREADS;
    let begin = min(thread * per_thread, count);
    let end = min(begin + per_thread, count);
    let passes = (params.key_bits + SMALL_RADIX_BITS - 1u) / SMALL_RADIX_BITS;

    for (var sort_pass = 0u; sort_pass < passes; sort_pass++) {
        let shift = sort_pass * SMALL_RADIX_BITS;
        let digit_mask = (1u << min(params.key_bits - shift, SMALL_RADIX_BITS)) - 1u;
        let from_caller = sort_pass % 2u == 0u;

        var counts: array<u32, SMALL_RADIX_BINS>;
        for (var i = begin; i < end; i++) {
            let digit = (pass_key(i, from_caller) >> shift) & digit_mask;
            counts[digit] += 1u;
        }
        for (var digit = 0u; digit < SMALL_RADIX_BINS; digit++) {
            offsets[digit * SMALL_SORT_THREADS + thread] = counts[digit];
        }
        workgroupBarrier();

        // Exclusive sum over all 1024 offsets: each thread a run of 16, then the runs' totals.
        let run_begin = thread * SMALL_SCAN_RUN;
        var run_sum = 0u;
        for (var i = 0u; i < SMALL_SCAN_RUN; i++) {
            let here = offsets[run_begin + i];
            offsets[run_begin + i] = run_sum;
            run_sum += here;
        }
        run_totals[thread] = run_sum;
        workgroupBarrier();
        var run_base = 0u;
        for (var earlier = 0u; earlier < thread; earlier++) {
            run_base += run_totals[earlier];
        }
        for (var i = 0u; i < SMALL_SCAN_RUN; i++) {
            offsets[run_begin + i] += run_base;
        }
        workgroupBarrier();

        var next: array<u32, SMALL_RADIX_BINS>;
        for (var digit = 0u; digit < SMALL_RADIX_BINS; digit++) {
            next[digit] = offsets[digit * SMALL_SORT_THREADS + thread];
        }
        for (var i = begin; i < end; i++) {
            let key = pass_key(i, from_caller);
            let digit = (key >> shift) & digit_mask;
            write_pair(next[digit], key, pass_value(i, from_caller), !from_caller);
            next[digit] += 1u;
        }
        // The next pass reads what other threads wrote; the offsets are rewritten too.
        storageBarrier();
        workgroupBarrier();
    }

    if passes % 2u == 1u {
        for (var i = begin; i < end; i++) {
            keys[i] = scratch_keys[i];
            values[i] = scratch_values[i];
        }
    }
}
