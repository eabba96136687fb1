// What both GEMM kernels of the deformation MLP share (mlp_gemm.wgsl on hardware GPUs,
// mlp_gemm_rows.wgsl on software adapters): C = epilogue(A B) with every operand addressed by an
// offset and two strides, so one kernel does the three products of a linear layer on row-major
// activations [rows, features] and PyTorch-layout weights [outputs, inputs]:
//   forward         Z[n, o]  = X[n, :] . W[o, :]   (+ bias, ReLU)
//   input gradient  dX[n, i] = dZ[n, :] . W[:, i]  (times ReLU'(X): mask > 0)
//   weight gradient dW[o, i] = dZ[:, o] . X[:, i]  (split over the summed rows: z = split, each
//                                                   writes its own partial, reduced in order, so
//                                                   the sum is deterministic)

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

// The summed rows [depth_begin, depth_end) of split `split`.
fn split_depth_range(split: u32) -> vec2<u32> {
    let begin = split * params.depth_per_split;
    return vec2<u32>(begin, min(params.depth, begin + params.depth_per_split));
}

// Stores C[row, col] of split `split` after the epilogue; outside the output it does nothing.
fn store_output(row: u32, col: u32, sum: f32, split: u32) {
    if row >= params.rows || col >= params.cols {
        return;
    }
    var value = sum;
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
