// Which tiles a splat is listed in (project_forward counts them, tile_emit writes them; both
// call these functions on the same stored values).
//
// A splat's footprint is where its alpha can reach ALPHA_MIN: sigma <= ln(opacity / ALPHA_MIN),
// an ellipse (plus FOOTPRINT_MARGIN, far above f32 rounding, so the rasterizer never meets a
// passing fragment outside it). Only tiles the ellipse touches are listed. A square of three
// standard deviations along the major axis (3DGS) lists many tiles in which no pixel can pass
// the alpha threshold: its corners, thin splats' long sides, and every low-opacity splat's rim.
// Listing only those tiles leaves every image and gradient unchanged and the intersections fewer,
// so the sort and both rasterize passes do less.

const FOOTPRINT_MARGIN: f32 = 0.01;

// The largest sigma at which the splat still passes the alpha threshold (<= 0: nowhere).
fn footprint_sigma(opacity: f32) -> f32 {
    return log(opacity / ALPHA_MIN) + FOOTPRINT_MARGIN;
}

// A splat's footprint, (1/2) d^T C d <= sigma_max around `mean`, with what every row needs
// computed once.
struct Footprint {
    mean: vec2<f32>,
    conic: vec3<f32>,
    sigma_max: f32,
    // det C.
    det: f32,
    // How far the ellipse reaches from the mean along x and y: sqrt(2 s (C^-1)_kk).
    reach: vec2<f32>,
}

fn splat_footprint(mean: vec2<f32>, conic: vec3<f32>, sigma_max: f32) -> Footprint {
    let det = conic.x * conic.z - conic.y * conic.y;
    let reach = sqrt(2.0 * sigma_max * vec2<f32>(conic.z, conic.x) / det);
    return Footprint(mean, conic, sigma_max, det, reach);
}

// Tile rows [x, y) the footprint spans, clamped to the grid (empty when off screen).
fn footprint_tile_rows(footprint: Footprint, grid: vec2<u32>) -> vec2<u32> {
    let rows = f32(grid.y);
    let first = clamp(floor((footprint.mean.y - footprint.reach.y) / f32(TILE_SIZE)), 0.0, rows);
    let end = clamp(ceil((footprint.mean.y + footprint.reach.y) / f32(TILE_SIZE)), 0.0, rows);
    return vec2<u32>(u32(first), u32(end));
}

// The footprint's x extent (left, right), in offsets from its mean, over the horizontal band
// of offsets [top, bottom] from its mean (left > right: the footprint misses the band). The
// footprint's slice through a band is convex, so this is exactly the x range it covers there.
// Its right edge, x(dy) = (-b dy + sqrt(2 s a - det dy^2)) / a, is concave in dy and peaks at
// dy = -b reach_x / c, so over the band it peaks at that dy clamped into the band; the left edge
// likewise bottoms out at dy = b reach_x / c.
fn footprint_band_extent(footprint: Footprint, top: f32, bottom: f32) -> vec2<f32> {
    let conic = footprint.conic;
    let reach = footprint.reach;
    let band_top = max(top, -reach.y);
    let band_bottom = min(bottom, reach.y);
    if band_top > band_bottom {
        return vec2<f32>(1.0, -1.0);
    }
    let room = 2.0 * footprint.sigma_max * conic.x;
    let y_right = clamp(-conic.y * reach.x / conic.z, band_top, band_bottom);
    let y_left = clamp(conic.y * reach.x / conic.z, band_top, band_bottom);
    let right = (-conic.y * y_right + sqrt(max(room - footprint.det * y_right * y_right, 0.0))) / conic.x;
    let left = (-conic.y * y_left - sqrt(max(room - footprint.det * y_left * y_left, 0.0))) / conic.x;
    return vec2<f32>(left, right);
}

// Tile columns [x, y) the footprint touches in tile row `row` (x >= y: none).
fn footprint_tile_columns(footprint: Footprint, row: u32, grid_x: u32) -> vec2<u32> {
    let extent = footprint_band_extent(
        footprint,
        f32(row * TILE_SIZE) - footprint.mean.y,
        f32((row + 1u) * TILE_SIZE) - footprint.mean.y,
    );
    if extent.x > extent.y {
        return vec2<u32>(0u);
    }
    let columns = f32(grid_x);
    let first = clamp(floor((footprint.mean.x + extent.x) / f32(TILE_SIZE)), 0.0, columns);
    let end = clamp(ceil((footprint.mean.x + extent.y) / f32(TILE_SIZE)), 0.0, columns);
    return vec2<u32>(u32(first), u32(end));
}
