// C = epilogue(A B) for the deformation MLP on hardware GPUs (mlp_gemm_common.wgsl has the
// products and the epilogue): a 64x64 output tile per workgroup, 16x16 threads with 4x4 outputs
// each, A and B staged through workgroup memory 16 deep.

const TILE: u32 = 64u;
const DEPTH_TILE: u32 = 16u;

// [depth][row] and [depth][col]: the inner loop reads 4 consecutive rows / cols.
var<workgroup> a_tile: array<f32, 1024>;
var<workgroup> b_tile: array<f32, 1024>;

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
    // Load order follows the unit stride so neighbouring threads read neighbouring addresses.
    let a_depth_fast = params.a_depth_stride == 1u;
    let b_depth_fast = params.b_depth_stride == 1u;

    var acc: array<f32, 16>;
    for (var k0 = depth_begin; k0 < depth_end; k0 += DEPTH_TILE) {
        for (var e = 0u; e < 4u; e++) {
            let flat = thread + e * 256u;
            var i = flat % TILE;
            var kk = flat / TILE;
            if a_depth_fast {
                i = flat / DEPTH_TILE;
                kk = flat % DEPTH_TILE;
            }
            let row = row0 + i;
            let k = k0 + kk;
            var value = 0.0;
            if row < params.rows && k < depth_end {
                value = a[params.a_offset + row * params.a_row_stride + k * params.a_depth_stride];
            }
            a_tile[kk * TILE + i] = value;

            var j = flat % TILE;
            var kb = flat / TILE;
            if b_depth_fast {
                j = flat / DEPTH_TILE;
                kb = flat % DEPTH_TILE;
            }
            let col = col0 + j;
            let kbk = k0 + kb;
            var b_value = 0.0;
            if col < params.cols && kbk < depth_end {
                b_value = b[params.b_offset + kbk * params.b_depth_stride + col * params.b_col_stride];
            }
            b_tile[kb * TILE + j] = b_value;
        }
        workgroupBarrier();
        for (var kk = 0u; kk < DEPTH_TILE; kk++) {
            let a_base = kk * TILE + local.y * 4u;
            let b_base = kk * TILE + local.x * 4u;
            let a_values = vec4<f32>(a_tile[a_base], a_tile[a_base + 1u], a_tile[a_base + 2u], a_tile[a_base + 3u]);
            let b_values = vec4<f32>(b_tile[b_base], b_tile[b_base + 1u], b_tile[b_base + 2u], b_tile[b_base + 3u]);
            for (var r = 0u; r < 4u; r++) {
                for (var cc = 0u; cc < 4u; cc++) {
                    acc[r * 4u + cc] = fma(a_values[r], b_values[cc], acc[r * 4u + cc]);
                }
            }
        }
        workgroupBarrier();
    }

    for (var r = 0u; r < 4u; r++) {
        for (var cc = 0u; cc < 4u; cc++) {
            store_output(row0 + local.y * 4u + r, col0 + local.x * 4u + cc, acc[r * 4u + cc], split);
        }
    }
}
