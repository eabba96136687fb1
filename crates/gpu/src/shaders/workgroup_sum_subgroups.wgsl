// Exclusive prefix sum of one u32 per thread over the workgroup, for software adapters: subgroup
// scans within each subgroup, then one invocation sums the subgroups' totals, so two barriers
// instead of workgroup_sum_shared.wgsl's 2 log2(SUM_THREADS). A CPU adapter runs a barrier by
// switching between every subgroup of the workgroup, which costs more than the arithmetic here
// (lavapipe, 512 px, 200k Gaussians: radix-sort scatter 55-58 -> 45-47 ms a step). Assumes what
// lavapipe does: subgroups are consecutive runs of threads, lanes in thread order. Must be called
// by every thread in uniform control flow. The including kernel defines SUM_THREADS.

var<workgroup> sum_subgroup_offsets: array<u32, SUM_THREADS>;

fn workgroup_exclusive_sum(thread: u32, value: u32) -> u32 {
    let lanes = subgroupAdd(1u);
    let subgroup = thread / lanes;
    let within = subgroupExclusiveAdd(value);
    let total = subgroupAdd(value);
    if thread % lanes == 0u {
        sum_subgroup_offsets[subgroup] = total;
    }
    workgroupBarrier();
    if thread == 0u {
        var offset = 0u;
        for (var s = 0u; s < SUM_THREADS / lanes; s++) {
            let subgroup_total = sum_subgroup_offsets[s];
            sum_subgroup_offsets[s] = offset;
            offset += subgroup_total;
        }
    }
    workgroupBarrier();
    return sum_subgroup_offsets[subgroup] + within;
}
