// The deformation field's input for one chunk of Gaussians: row n of `encoded` (row stride given)
// becomes [gamma(x), gamma(t)] of Gaussian first + n, where gamma(p) = [p, sin(2^0 p), cos(2^0 p),
// ..., sin(2^(L-1) p), cos(2^(L-1) p)], each term over all components (the NeRF embedder's order).

struct EncodeParams {
    count: u32,
    first: u32,
    row_stride: u32,
    position_frequencies: u32,
    time_frequencies: u32,
    time: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: EncodeParams;
@group(0) @binding(1) var<storage, read> means: array<f32>;
@group(0) @binding(2) var<storage, read_write> encoded: array<f32>;

@compute @workgroup_size(256, 1, 1)
fn deform_encode(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let n = (group.x + group.y * groups.x) * 256u + thread;
    if n >= params.count {
        return;
    }
    let g = params.first + n;
    let x = vec3<f32>(means[3u * g], means[3u * g + 1u], means[3u * g + 2u]);
    var at = n * params.row_stride;
    encoded[at] = x.x;
    encoded[at + 1u] = x.y;
    encoded[at + 2u] = x.z;
    at += 3u;
    for (var level = 0u; level < params.position_frequencies; level++) {
        let scaled = x * f32(1u << level);
        let s = sin(scaled);
        let c = cos(scaled);
        encoded[at] = s.x;
        encoded[at + 1u] = s.y;
        encoded[at + 2u] = s.z;
        encoded[at + 3u] = c.x;
        encoded[at + 4u] = c.y;
        encoded[at + 5u] = c.z;
        at += 6u;
    }
    let t = params.time;
    encoded[at] = t;
    at += 1u;
    for (var level = 0u; level < params.time_frequencies; level++) {
        let scaled = t * f32(1u << level);
        encoded[at] = sin(scaled);
        encoded[at + 1u] = cos(scaled);
        at += 2u;
    }
}
