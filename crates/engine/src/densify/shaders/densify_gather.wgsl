// Re-lays out one per-Gaussian array of `words` 32-bit words a row into a new buffer: every
// output row copies its source row; with `fresh_zero` (optimiser moments) rows that are not
// the Gaussian itself (clones, split children) start at zero instead. Split children's means
// and scales are then moved by densify_split.wgsl.

struct Gather {
    words: u32,
    fresh_zero: u32,
    new_count: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> gather: Gather;
@group(0) @binding(1) var<storage, read> origin_source: array<u32>;
@group(0) @binding(2) var<storage, read> origin_kind: array<u32>;
@group(0) @binding(3) var<storage, read> rows_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> rows_out: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let t = gid.x + gid.y * groups.x * 256u;
    if t >= gather.new_count * gather.words {
        return;
    }
    let row = t / gather.words;
    let word = t - row * gather.words;
    let fresh = origin_kind[row] != 0u;
    var value = 0u;
    if !(fresh && gather.fresh_zero != 0u) {
        value = rows_in[origin_source[row] * gather.words + word];
    }
    rows_out[t] = value;
}
