// C = epilogue(A B) for the deformation MLP on hardware GPUs (mlp_gemm_common.wgsl has the
// products and the epilogue): a 64x64 output tile per workgroup of 16x16 invocations, each
// invocation 4x4 outputs in four vec4 accumulators. A's and B's depth tiles (16 deep) are staged
// through workgroup memory as vec4s of four rows of A and four columns of B, so a step of the
// inner loop is two vec4 reads and sixteen multiply-adds. Nothing private is indexed by a loop
// variable: a compiler that cannot prove such an index constant keeps the array in memory
// instead of registers.

const TILE: u32 = 64u;
const DEPTH_TILE: u32 = 16u;
// vec4s across a tile side, and per depth row of the staged tiles: one vec4 of padding, so the
// staging's writes (sixteen depths of one quad at a time) fall on different banks.
const QUADS: u32 = 16u;
const QUAD_STRIDE: u32 = 17u;

// [depth][quad]: quad q holds rows (columns) 4q..4q+3 of the tile at that depth.
var<workgroup> a_tile: array<vec4<f32>, 272>;
var<workgroup> b_tile: array<vec4<f32>, 272>;

// A[row, k] of the product, 0 outside it (a partial tile).
fn load_a(row: u32, k: u32, depth_end: u32) -> f32 {
    if row < params.rows && k < depth_end {
        return a[params.a_offset + row * params.a_row_stride + k * params.a_depth_stride];
    }
    return 0.0;
}

// B[k, col] of the product, 0 outside it.
fn load_b(k: u32, col: u32, depth_end: u32) -> f32 {
    if col < params.cols && k < depth_end {
        return b[params.b_offset + k * params.b_depth_stride + col * params.b_col_stride];
    }
    return 0.0;
}

fn store_quad(row: u32, col: u32, sums: vec4<f32>, split: u32) {
    store_output(row, col, sums.x, split);
    store_output(row, col + 1u, sums.y, split);
    store_output(row, col + 2u, sums.z, split);
    store_output(row, col + 3u, sums.w, split);
}

@compute @workgroup_size(16, 16, 1)
fn gemm(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let row0 = group.y * TILE;
    let col0 = group.x * TILE;
    let split = group.z;
    let depth_range = split_depth_range(split);
    let depth_begin = depth_range.x;
    let depth_end = depth_range.y;
    // Each invocation stages one quad of A and one of B per depth tile. Which of depth and quad
    // varies fastest between neighbouring invocations follows the operand's unit stride, so they
    // read neighbouring addresses.
    var a_k = thread / QUADS;
    var a_quad = thread % QUADS;
    if params.a_depth_stride == 1u {
        a_k = thread % DEPTH_TILE;
        a_quad = thread / DEPTH_TILE;
    }
    var b_k = thread / QUADS;
    var b_quad = thread % QUADS;
    if params.b_depth_stride == 1u {
        b_k = thread % DEPTH_TILE;
        b_quad = thread / DEPTH_TILE;
    }
    let a_row = row0 + a_quad * 4u;
    let b_col = col0 + b_quad * 4u;

    var acc0 = vec4<f32>();
    var acc1 = vec4<f32>();
    var acc2 = vec4<f32>();
    var acc3 = vec4<f32>();
    for (var k0 = depth_begin; k0 < depth_end; k0 += DEPTH_TILE) {
        let ak = k0 + a_k;
        a_tile[a_k * QUAD_STRIDE + a_quad] = vec4<f32>(
            load_a(a_row, ak, depth_end),
            load_a(a_row + 1u, ak, depth_end),
            load_a(a_row + 2u, ak, depth_end),
            load_a(a_row + 3u, ak, depth_end),
        );
        let bk = k0 + b_k;
        b_tile[b_k * QUAD_STRIDE + b_quad] = vec4<f32>(
            load_b(bk, b_col, depth_end),
            load_b(bk, b_col + 1u, depth_end),
            load_b(bk, b_col + 2u, depth_end),
            load_b(bk, b_col + 3u, depth_end),
        );
        workgroupBarrier();
        for (var kk = 0u; kk < DEPTH_TILE; kk++) {
            let rows = a_tile[kk * QUAD_STRIDE + local.y];
            let cols = b_tile[kk * QUAD_STRIDE + local.x];
            acc0 = fma(vec4<f32>(rows.x), cols, acc0);
            acc1 = fma(vec4<f32>(rows.y), cols, acc1);
            acc2 = fma(vec4<f32>(rows.z), cols, acc2);
            acc3 = fma(vec4<f32>(rows.w), cols, acc3);
        }
        workgroupBarrier();
    }

    let row = row0 + local.y * 4u;
    let col = col0 + local.x * 4u;
    store_quad(row, col, acc0, split);
    store_quad(row + 1u, col, acc1, split);
    store_quad(row + 2u, col, acc2, split);
    store_quad(row + 3u, col, acc3, split);
}
