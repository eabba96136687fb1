// How the column kernels (rasterize_*_columns.wgsl, software adapters) walk a tile's splats:
// each subgroup on its own, a chunk of splats at a time, with no workgroup memory and no barriers.
//
// A CPU adapter such as lavapipe runs a subgroup's invocations as the lanes of SIMD registers,
// but inside loops it reads memory lane by lane (a scalar load behind a test of each lane's
// mask), so a value every lane reads costs as much as a different value per lane. Here each lane
// reads a different splat of the tile's list, one chunk is a splat per lane, and the chunk's
// splats reach every lane by shuffles, which lavapipe compiles to one vector permute each.
//
// Each lane also tests its splat's footprint (tile_footprint.wgsl) against the block of pixels
// the subgroup covers, and the walk visits only the chunk's splats that reach the block: a splat
// listed in a 16x16 tile misses most of the tile's 8x8 blocks. The footprint holds every
// fragment that passes the alpha threshold, so the skipped ones contribute nothing.
//
// lavapipe, 512 px, 200k random Gaussians, ms per pass (docs/benchmarks.md): column backward
// 551 with batches staged in workgroup memory, 300 with lane chunks, 195 with the block test;
// column forward 145, 107 and 72.

// Ballots are read from their first word, so a chunk has at most 32 splats.
const CHUNK_LANES_MAX: u32 = 32u;

struct LaneSplat {
    gaussian: u32,
    mean_opacity: vec4<f32>,
    conic: vec3<f32>,
    colour: vec3<f32>,
}

// The splat at position `intersection` of the sorted intersection list.
fn load_lane_splat(intersection: u32) -> LaneSplat {
    let gaussian = intersection_gaussians[intersection];
    return LaneSplat(
        gaussian,
        projected[3u * gaussian],
        projected[3u * gaussian + 1u].xyz,
        projected[3u * gaussian + 2u].xyz,
    );
}

// The box of pixel centres (min x, min y, max x, max y) the subgroup covers, from each
// invocation's first and last pixel centre. Called in uniform control flow.
fn subgroup_block(first_centre: vec2<f32>, last_centre: vec2<f32>) -> vec4<f32> {
    return vec4<f32>(subgroupMin(first_centre), subgroupMax(last_centre));
}

// Whether the splat's footprint reaches into `block` (subgroup_block).
fn splat_reaches_block(splat: LaneSplat, block: vec4<f32>) -> bool {
    let sigma_max = footprint_sigma(splat.mean_opacity.z);
    let mean = splat.mean_opacity.xy;
    let footprint = splat_footprint(mean, splat.conic, sigma_max);
    let extent = footprint_band_extent(footprint, block.y - mean.y, block.w - mean.y);
    return sigma_max > 0.0 && extent.x <= extent.y && mean.x + extent.y >= block.x
        && mean.x + extent.x <= block.z;
}

// The lanes of the chunk whose splat is `wanted`, a bit per lane. Called in uniform control flow.
fn chunk_lanes_wanted(wanted: bool, lane: u32) -> u32 {
    return subgroupBallot(wanted && lane < CHUNK_LANES_MAX).x;
}

// The lowest lane left in `pending`, which it clears.
fn next_chunk_lane(pending: ptr<function, u32>) -> u32 {
    let lane = firstTrailingBit(*pending);
    *pending &= *pending - 1u;
    return lane;
}

// Lane `lane`'s splat, in every lane. Called in uniform control flow.
fn splat_from_lane(own: LaneSplat, lane: u32) -> LaneSplat {
    return LaneSplat(
        subgroupShuffle(own.gaussian, lane),
        subgroupShuffle(own.mean_opacity, lane),
        subgroupShuffle(own.conic, lane),
        subgroupShuffle(own.colour, lane),
    );
}
