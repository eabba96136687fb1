// C = epilogue(A B) for the deformation MLP on software adapters (mlp_gemm_common.wgsl has the
// products and the epilogue), computed as a 4 x 8 block of outputs per invocation held in
// registers, with no workgroup memory and no barrier. A CPU adapter runs a workgroup's
// invocations as SIMD lanes in a loop, and inside the depth loop lavapipe reads memory lane by
// lane even where every lane reads the same address (measured: with the weights' loads replaced
// by constants a row-per-lane version ran 7x faster), so what counts is multiply-adds per element
// read: 32 per 12 here. The tiled kernel's barrier every 16 depth steps costs more on a CPU than
// its reuse saves (8 x 256 field, 1443 Gaussians, lavapipe: forward 486 ms tiled, 140 ms here).

// Invocations per workgroup, set by the host per product (kernels.rs, `ROWS_LANES`): rows past
// a product's end are computed and not stored, so a weight gradient's few rows (a layer's
// outputs) take a workgroup only as tall as they need.
override LANES: u32 = 64u;
const ROWS_PER_LANE: u32 = 4u;
const COLS_PER_LANE: u32 = 8u;

fn store_row(row: u32, col0: u32, low: vec4<f32>, high: vec4<f32>, split: u32) {
    store_output(row, col0, low.x, split);
    store_output(row, col0 + 1u, low.y, split);
    store_output(row, col0 + 2u, low.z, split);
    store_output(row, col0 + 3u, low.w, split);
    store_output(row, col0 + 4u, high.x, split);
    store_output(row, col0 + 5u, high.y, split);
    store_output(row, col0 + 6u, high.z, split);
    store_output(row, col0 + 7u, high.w, split);
}

@compute @workgroup_size(LANES, 1, 1)
fn gemm_rows(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
) {
    let row0 = (group.y * LANES + local.x) * ROWS_PER_LANE;
    let col0 = group.x * COLS_PER_LANE;
    let split = group.z;
    let depth_range = split_depth_range(split);
    let depth_begin = depth_range.x;
    let depth_end = depth_range.y;
    // Rows and columns past the ends read a valid element (clamped) and are not stored, so the
    // loop has no per-lane branch.
    let last_row = max(params.rows, 1u) - 1u;
    let last_col = max(params.cols, 1u) - 1u;
    let rows = min(vec4<u32>(0u, 1u, 2u, 3u) + row0, vec4<u32>(last_row)) * params.a_row_stride;
    let first_col = vec4<u32>(0u, 1u, 2u, 3u) + col0;
    let cols_low = min(first_col, vec4<u32>(last_col)) * params.b_col_stride;
    let cols_high = min(first_col + 4u, vec4<u32>(last_col)) * params.b_col_stride;

    var low0 = vec4<f32>(0.0);
    var low1 = vec4<f32>(0.0);
    var low2 = vec4<f32>(0.0);
    var low3 = vec4<f32>(0.0);
    var high0 = vec4<f32>(0.0);
    var high1 = vec4<f32>(0.0);
    var high2 = vec4<f32>(0.0);
    var high3 = vec4<f32>(0.0);
    var a_depth = params.a_offset + depth_begin * params.a_depth_stride;
    var b_depth = params.b_offset + depth_begin * params.b_depth_stride;
    for (var k = depth_begin; k < depth_end; k++) {
        let x = vec4<f32>(a[a_depth + rows.x], a[a_depth + rows.y], a[a_depth + rows.z], a[a_depth + rows.w]);
        let w_low = vec4<f32>(b[b_depth + cols_low.x], b[b_depth + cols_low.y], b[b_depth + cols_low.z], b[b_depth + cols_low.w]);
        let w_high = vec4<f32>(b[b_depth + cols_high.x], b[b_depth + cols_high.y], b[b_depth + cols_high.z], b[b_depth + cols_high.w]);
        low0 = fma(vec4<f32>(x.x), w_low, low0);
        high0 = fma(vec4<f32>(x.x), w_high, high0);
        low1 = fma(vec4<f32>(x.y), w_low, low1);
        high1 = fma(vec4<f32>(x.y), w_high, high1);
        low2 = fma(vec4<f32>(x.z), w_low, low2);
        high2 = fma(vec4<f32>(x.z), w_high, high2);
        low3 = fma(vec4<f32>(x.w), w_low, low3);
        high3 = fma(vec4<f32>(x.w), w_high, high3);
        a_depth += params.a_depth_stride;
        b_depth += params.b_depth_stride;
    }

    store_row(row0, col0, low0, high0, split);
    store_row(row0 + 1u, col0, low1, high1, split);
    store_row(row0 + 2u, col0, low2, high2, split);
    store_row(row0 + 3u, col0, low3, high3, split);
}
