// Exclusive prefix sum of one u32 per thread over the workgroup, in workgroup memory
// (Hillis-Steele: log2(SUM_THREADS) rounds of two barriers). The including kernel defines
// SUM_THREADS, its workgroup size. The other way: workgroup_sum_subgroups.wgsl.

var<workgroup> sum_thread_totals: array<u32, SUM_THREADS>;

fn workgroup_exclusive_sum(thread: u32, value: u32) -> u32 {
    sum_thread_totals[thread] = value;
    workgroupBarrier();
    for (var offset = 1u; offset < SUM_THREADS; offset = offset << 1u) {
        var earlier = 0u;
        if thread >= offset {
            earlier = sum_thread_totals[thread - offset];
        }
        workgroupBarrier();
        sum_thread_totals[thread] += earlier;
        workgroupBarrier();
    }
    return sum_thread_totals[thread] - value;
}
