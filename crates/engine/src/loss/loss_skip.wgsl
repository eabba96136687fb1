// Which pixels a pass computes: all of them for the full render's loss; for an object loss, those
// in SKIP_CELL x SKIP_CELL cells within the pass's reach of a cell with content (any non-zero
// rendered or masked target pixel). Expects a `tile_distance` binding (each slot's cells'
// Chebyshev distances to content, loss_work_lists.wgsl). The work lists leave out the tiles with
// no cell in a pass's reach; this decides cell by cell within the tiles listed.
//
// Each pass's reach is the least that keeps the loss and gradient exact. A cell at distance d >= 1
// is at least 8 (d - 1) + 1 pixels from every content pixel along one axis, so:
// - pass 1 (row moments) and pass 2 (the SSIM terms and the loss): non-zero only within the
//   window's radius (5 px) of content, so reach 1 (a cell at distance 2 is 9 px away);
// - pass 3 (row-filtered partials): d_mu is non-zero within 5 px of content and its row filter
//   within 10 px along the row, so reach 2 (a cell at distance 3 is 17 px away); pass 4 (the
//   gradient) is non-zero within 10 px of content, so reach 2 too.
// A pass reading its predecessor's output up to 5 px away may reach a cell the predecessor
// skipped, where the buffer still holds another object's values. The readers take those inputs
// as zero (`run_reach`, `input_computed`), which is exact: beyond its pass's reach the row and
// full moments are zero, and so is d_mu, the only SSIM partial that meets a non-content pixel;
// d_rr and d_rt are multiplied by the pixel's own colours, and a content pixel's gradient reads
// partials only from within 5 px of it in each axis, all within reach 1 of its cell.

const REACH_ROW_MOMENTS: u32 = 1u;
const REACH_SSIM: u32 = 1u;
const REACH_ROW_PARTIALS: u32 = 2u;
const REACH_GRADIENT: u32 = 2u;
// Distances are capped here: only "within the largest reach" or "beyond" matters.
const LOSS_SKIP_CAP: u32 = REACH_GRADIENT + 1u;

fn cell_in_reach(x: i32, y: i32, reach: u32) -> bool {
    if params.use_mask == 0u {
        return true;
    }
    let cells = cell_grid();
    let cell = u32(y) / SKIP_CELL * cells.x + u32(x) / SKIP_CELL;
    return tile_distance[slot * cells.x * cells.y + cell] <= reach;
}

// Whether the inputs of a run were computed by the pass that wrote them. A run reads RUN_INPUTS
// pixels along one axis, from WINDOW_RADIUS before its start to WINDOW_RADIUS past its end; runs
// start at multiples of SKIP_CELL = LOSS_RUN, so that span covers its own cell and at most the
// cells before and after it.
struct RunReach {
    // The axis coordinates where the run's own cell and the next start.
    own_start: i32,
    next_start: i32,
    before: bool,
    own: bool,
    after: bool,
}

// The reach of the run at (x, y) along `step` ((1, 0) or (0, 1)) for inputs a pass with reach
// `input_reach` wrote; `along` is the run's first coordinate on that axis and `extent` the
// image's size on it.
fn run_reach(x: i32, y: i32, step: vec2<i32>, along: i32, extent: i32, input_reach: u32) -> RunReach {
    let across = vec2<i32>(x, y) * (vec2<i32>(1) - step);
    let before = across + step * max(along - 1, 0);
    let after = across + step * min(along + i32(SKIP_CELL), extent - 1);
    return RunReach(
        along,
        along + i32(SKIP_CELL),
        cell_in_reach(before.x, before.y, input_reach),
        cell_in_reach(x, y, input_reach),
        cell_in_reach(after.x, after.y, input_reach),
    );
}

// Whether the input at axis coordinate `coordinate` of a run was computed.
fn input_computed(reach: RunReach, coordinate: i32) -> bool {
    if coordinate < reach.own_start {
        return reach.before;
    }
    return select(reach.after, reach.own, coordinate < reach.next_start);
}

const_assert SKIP_CELL == LOSS_RUN && u32(WINDOW_RADIUS) <= SKIP_CELL && LOSS_TILE % SKIP_CELL == 0u;
