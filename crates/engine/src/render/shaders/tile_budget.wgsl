// One invocation: reads the total intersection count from the scan, clamps it to the buffer
// capacity for the kernels and the sort that follow, writes their indirect dispatch size, and
// records the unclamped total (running maximum) so the host can grow the capacity.
//
// counts[0] = Gaussian count (written by the host), counts[1] = intersections to process,
// counts[2..5] = indirect workgroup counts for one invocation per intersection (256 per group),
// counts[5] = unclamped total of this render.
// peak_intersections[0] = running maximum of the unclamped totals since the host last cleared
// it, [1] = renders clamped so far (their total exceeded the capacity, so tile entries were
// dropped; never cleared, so no read-back copy's count is lost).

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> tile_offsets: array<u32>;
@group(0) @binding(2) var<storage, read_write> counts: array<u32>;
@group(0) @binding(3) var<storage, read_write> peak_intersections: array<atomic<u32>>;

const MAX_GROUPS_PER_DIMENSION: u32 = 65535u;

@compute @workgroup_size(1)
fn tile_budget() {
    let total = tile_offsets[uniforms.gaussian_count];
    let kept = min(total, uniforms.intersection_capacity);
    counts[1] = kept;
    let groups = max((kept + 255u) / 256u, 1u);
    if groups <= MAX_GROUPS_PER_DIMENSION {
        counts[2] = groups;
        counts[3] = 1u;
    } else {
        counts[2] = MAX_GROUPS_PER_DIMENSION;
        counts[3] = (groups + MAX_GROUPS_PER_DIMENSION - 1u) / MAX_GROUPS_PER_DIMENSION;
    }
    counts[4] = 1u;
    counts[5] = total;
    atomicMax(&peak_intersections[0], total);
    if total > uniforms.intersection_capacity {
        atomicAdd(&peak_intersections[1], 1u);
    }
}
