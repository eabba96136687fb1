// C = epilogue(A B) for the deformation MLP: a 64x64 output tile per workgroup, 16x16 threads with
// 4x4 outputs each, A and B staged through workgroup memory 16 deep.
//
// Every operand is addressed by an offset and two strides, so one kernel does the three products
// of a linear layer on row-major activations [rows, features] and PyTorch-layout weights
// [outputs, inputs]:
//   forward         Z[n, o]  = X[n, :] . W[o, :]   (+ bias, ReLU)
//   input gradient  dX[n, i] = dZ[n, :] . W[:, i]  (times ReLU'(X): mask > 0)
//   weight gradient dW[o, i] = dZ[:, o] . X[:, i]  (split over the summed rows: z = split, each
//                                                   writes its own partial, reduced in order, so
//                                                   the sum is deterministic)

const TILE: u32 = 64u;
const DEPTH_TILE: u32 = 16u;
const FLAG_BIAS: u32 = 1u;
const FLAG_RELU: u32 = 2u;
const FLAG_MASK: u32 = 4u;

struct GemmParams {
    rows: u32,
    cols: u32,
    depth: u32,
    depth_per_split: u32,
    a_offset: u32,
    a_row_stride: u32,
    a_depth_stride: u32,
    b_offset: u32,
    b_depth_stride: u32,
    b_col_stride: u32,
    c_offset: u32,
    c_row_stride: u32,
    c_split_stride: u32,
    bias_offset: u32,
    mask_offset: u32,
    mask_row_stride: u32,
    flags: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: GemmParams;
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
@group(0) @binding(3) var<storage, read> bias: array<f32>;
@group(0) @binding(4) var<storage, read> mask: array<f32>;
@group(0) @binding(5) var<storage, read_write> c: array<f32>;

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
    let depth_begin = split * params.depth_per_split;
    let depth_end = min(params.depth, depth_begin + params.depth_per_split);
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
        let row = row0 + local.y * 4u + r;
        if row >= params.rows {
            continue;
        }
        for (var cc = 0u; cc < 4u; cc++) {
            let col = col0 + local.x * 4u + cc;
            if col >= params.cols {
                continue;
            }
            var value = acc[r * 4u + cc];
            if (params.flags & FLAG_BIAS) != 0u {
                value += bias[params.bias_offset + col];
            }
            if (params.flags & FLAG_RELU) != 0u {
                value = max(value, 0.0);
            }
            if (params.flags & FLAG_MASK) != 0u {
                if mask[params.mask_offset + row * params.mask_row_stride + col] <= 0.0 {
                    value = 0.0;
                }
            }
            c[params.c_offset + split * params.c_split_stride + row * params.c_row_stride + col] = value;
        }
    }
}
