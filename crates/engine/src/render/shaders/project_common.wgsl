// Shared by every render kernel: the per-render uniforms and the projected-splat layout.
//
// projected[3 i + 0] = (mean x, mean y, opacity, camera depth)
// projected[3 i + 1] = (conic a, conic b, conic c, radius in pixels; 0 = culled)
// projected[3 i + 2] = (red, green, blue, 0)
//
// grad_projected holds GRAD_STRIDE floats per Gaussian:
// 0-1 d/d mean2d, 2-4 d/d conic, 5-7 d/d colour, 8 d/d opacity, 9-10 sum |d/d mean2d|.

const TILE_SIZE: u32 = 16u;
// Side of the squares whose occupancy an object render marks (`mark_occupancy`).
const OCCUPANCY_CELL: u32 = 8u;
const GRAD_STRIDE: u32 = 12u;
const ALPHA_MIN: f32 = 0.003921568627451; // 1 / 255
const ALPHA_MAX: f32 = 0.99;
const TRANSMITTANCE_MIN: f32 = 0.0001;
const COVARIANCE_DILATION: f32 = 0.3;
const RADIUS_SIGMAS: f32 = 3.0;
const CULLED_KEY: u32 = 0xffffffffu;

struct RenderUniforms {
    camera_from_world: mat4x4<f32>,
    camera_position: vec4<f32>,
    background: vec4<f32>,
    focal: vec2<f32>,
    principal: vec2<f32>,
    image_size: vec2<u32>,
    tile_grid: vec2<u32>,
    near: f32,
    far: f32,
    sh_degree: u32,
    gaussian_count: u32,
    filter_level: u32,
    filter_id: u32,
    filter_enabled: u32,
    intersection_capacity: u32,
    // FRUSTUM_SLACK x the half field of view the Jacobian clamps to (the whole image's, for a
    // band of one): RenderCamera::jacobian_limit.
    jacobian_limit: vec2<f32>,
    // 1 where the rasterize backward also sums |d loss / d mean2d| (the densification statistic,
    // which the full render's loss alone feeds); 0 for object renders.
    mean2d_abs: u32,
    // 1 where the rasterize forward marks the OCCUPANCY_CELL squares with a non-zero colour
    // (object renders, for the object loss's skipping); 0 for the full render.
    mark_occupancy: u32,
}

// Flat invocation index of a 1D workload split over x and y workgroups (see `workgroups_2d`).
fn flat_index(gid: vec3<u32>, num_groups: vec3<u32>, group_size: u32) -> u32 {
    return gid.x + gid.y * num_groups.x * group_size;
}

// Rotation matrix of the normalised quaternion (w, x, y, z).
fn rotation_from_quaternion(q: vec4<f32>) -> mat3x3<f32> {
    let w = q.x;
    let x = q.y;
    let y = q.z;
    let z = q.w;
    // Columns.
    return mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
}

fn camera_rotation(u: RenderUniforms) -> mat3x3<f32> {
    return mat3x3<f32>(
        u.camera_from_world[0].xyz,
        u.camera_from_world[1].xyz,
        u.camera_from_world[2].xyz,
    );
}

// The perspective Jacobian at camera-space point p with x/z, y/z clamped to the slack frustum.
// Returns the 3x2 matrix whose columns are J's rows transposed: J = transpose(result).
struct Jacobian {
    row0: vec3<f32>,
    row1: vec3<f32>,
    clamped_x: bool,
    clamped_y: bool,
    tan_clamped: vec2<f32>,
}

fn perspective_jacobian(u: RenderUniforms, p: vec3<f32>) -> Jacobian {
    let limit = u.jacobian_limit;
    let ratio = p.xy / p.z;
    let clamped = clamp(ratio, -limit, limit);
    let t = clamped * p.z;
    var j: Jacobian;
    j.row0 = vec3<f32>(u.focal.x / p.z, 0.0, -u.focal.x * t.x / (p.z * p.z));
    j.row1 = vec3<f32>(0.0, u.focal.y / p.z, -u.focal.y * t.y / (p.z * p.z));
    j.clamped_x = ratio.x != clamped.x;
    j.clamped_y = ratio.y != clamped.y;
    j.tan_clamped = clamped;
    return j;
}

// The exponent of a splat's Gaussian at offset `d` from its mean (conic = inverse covariance
// as (a, b, c)); negative only through rounding, which the kernels skip.
fn splat_sigma(conic: vec3<f32>, d: vec2<f32>) -> f32 {
    return 0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) + conic.y * d.x * d.y;
}
