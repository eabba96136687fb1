// The bindings both rasterize backward kernels share (rasterize_backward.wgsl, one pixel per
// invocation; rasterize_backward_columns.wgsl, columns of pixels on software adapters).

@group(0) @binding(0) var<uniform> uniforms: RenderUniforms;
@group(0) @binding(1) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(2) var<storage, read> intersection_gaussians: array<u32>;
@group(0) @binding(3) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> final_transmittance: array<f32>;
@group(0) @binding(5) var<storage, read> last_contributor: array<u32>;
@group(0) @binding(6) var<storage, read> grad_image: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> grad_projected: array<AtomicF32>;
