// Which loss tiles a pass computes (loss_distance.wgsl): all of them for the full render's loss;
// for an object loss, those within one tile of content. Expects a `tile_distance` binding.
//
// A pixel's loss is non-zero only within the window's radius (5 px) of content and its gradient
// within twice that, which one tile (16 px) covers. Every pass runs only there, so a pass reading
// its predecessor's output up to 5 px away may reach a tile the predecessor skipped, where the
// buffer still holds another object's values. The readers take those inputs as zero
// (`run_reach`, `input_computed`), which is exact: two tiles from content (at least 17 px
// along one axis) the moments are zero, and so is d_mu, the only SSIM partial that meets a
// pixel there; d_rr and d_rt are multiplied by the pixel's own colours, and a content pixel's
// gradient reads partials only from within 10 px of it, all within one tile of content.

// Tiles from content a pass computes.
const SKIP_REACH: u32 = 1u;
// Distances are capped here: only "within SKIP_REACH" or "beyond" matters.
const LOSS_SKIP_CAP: u32 = SKIP_REACH + 1u;

fn tile_in_reach(x: i32, y: i32, reach: u32) -> bool {
    if params.use_mask == 0u {
        return true;
    }
    let tiles_x = (params.width + LOSS_TILE - 1u) / LOSS_TILE;
    let tile = u32(y) / LOSS_TILE * tiles_x + u32(x) / LOSS_TILE;
    return tile_distance[tile] <= reach;
}

// Whether the inputs of a run were computed by the pass that wrote them. A run reads
// RUN_INPUTS pixels along one axis, from 5 before its start to 5 past its end; runs start at
// multiples of LOSS_RUN, so that span stays within two tiles: those before `boundary`
// (the axis coordinate where the second tile starts) in the first, the rest in the second.
struct RunReach {
    boundary: i32,
    first: bool,
    second: bool,
}

// The reach of the run at (x, y) along `step` ((1, 0) or (0, 1)); `along` is the run's first
// coordinate on that axis and `extent` the image's size on it.
fn run_reach(x: i32, y: i32, step: vec2<i32>, along: i32, extent: i32) -> RunReach {
    let first = clamp(along - WINDOW_RADIUS, 0, extent - 1);
    let last = clamp(along + RUN_INPUTS - 1 - WINDOW_RADIUS, 0, extent - 1);
    let across = vec2<i32>(x, y) * (vec2<i32>(1) - step);
    let first_pixel = across + step * first;
    let last_pixel = across + step * last;
    return RunReach(
        (first / i32(LOSS_TILE) + 1) * i32(LOSS_TILE),
        tile_in_reach(first_pixel.x, first_pixel.y, SKIP_REACH),
        tile_in_reach(last_pixel.x, last_pixel.y, SKIP_REACH),
    );
}

// Whether the input at axis coordinate `coordinate` of a run was computed.
fn input_computed(reach: RunReach, coordinate: i32) -> bool {
    return select(reach.second, reach.first, coordinate < reach.boundary);
}

// The span fits two tiles while the last run starting within WINDOW_RADIUS of a tile's start
// also ends WINDOW_RADIUS before the tile's end.
const_assert LOSS_TILE % LOSS_RUN == 0u
    && (u32(WINDOW_RADIUS) - 1u) / LOSS_RUN * LOSS_RUN + LOSS_RUN + u32(WINDOW_RADIUS) <= LOSS_TILE;
