// Bias gradients: per split of the rows, the column sums of dZ [rows, cols] (row stride given),
// written as partials [split][col] for mlp_split_reduce to add in a fixed order.

struct ColumnSumParams {
    rows: u32,
    cols: u32,
    rows_per_split: u32,
    source_offset: u32,
    source_row_stride: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: ColumnSumParams;
@group(0) @binding(1) var<storage, read> source: array<f32>;
@group(0) @binding(2) var<storage, read_write> partials: array<f32>;

@compute @workgroup_size(64, 1, 1)
fn column_sums(@builtin(global_invocation_id) id: vec3<u32>) {
    let col = id.x;
    let split = id.y;
    if col >= params.cols {
        return;
    }
    let begin = split * params.rows_per_split;
    let end = min(params.rows, begin + params.rows_per_split);
    var sum = 0.0;
    for (var row = begin; row < end; row++) {
        sum += source[params.source_offset + row * params.source_row_stride + col];
    }
    partials[split * params.cols + col] = sum;
}
