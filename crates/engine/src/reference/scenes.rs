//! Small deterministic scenes for tests and benchmarks: random Gaussians in front of a camera, plus
//! the cases a rasteriser gets wrong first (behind the camera, on tile borders, needle-thin, very
//! large, nearly transparent, high-order SH).

use glam::Mat4;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::model::SH_COEFFICIENTS;
use crate::{GaussianModel, OBJECT_NONE, RenderCamera};

/// A camera at the origin looking down +z, focal length `width`, principal point at the centre.
pub fn test_camera(width: u32, height: u32) -> RenderCamera {
    RenderCamera {
        width,
        height,
        fx: width as f32,
        fy: width as f32,
        cx: width as f32 * 0.5,
        cy: height as f32 * 0.5,
        camera_from_world: Mat4::IDENTITY,
        near: 0.01,
        far: 100.0,
        clamp_to: None,
    }
}

/// World point that `camera` (from [`test_camera`]) sees at pixel (u, v) and depth `z`.
pub fn point_at_pixel(camera: &RenderCamera, u: f32, v: f32, z: f32) -> [f32; 3] {
    [
        (u - camera.cx) / camera.fx * z,
        (v - camera.cy) / camera.fy * z,
        z,
    ]
}

fn random_quaternion(rng: &mut ChaCha8Rng) -> [f32; 4] {
    let q: [f32; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
    if q.iter().map(|v| v * v).sum::<f32>() < 0.05 {
        [1.0, 0.1, 0.0, 0.0]
    } else {
        q
    }
}

/// Appends one Gaussian with random rotation and SH (all 16 coefficients set).
#[allow(clippy::too_many_arguments)]
fn push_random(
    model: &mut GaussianModel,
    rng: &mut ChaCha8Rng,
    mean: [f32; 3],
    log_scale: [f32; 3],
    opacity_logit: f32,
    object_ids: [u32; 3],
) {
    let mut sh = [[0.0f32; 3]; SH_COEFFICIENTS];
    for (k, rgb) in sh.iter_mut().enumerate() {
        let amplitude = if k == 0 { 1.2 } else { 0.25 };
        *rgb = std::array::from_fn(|_| rng.random_range(-amplitude..amplitude));
    }
    model.means.push(mean);
    model.log_scales.push(log_scale);
    model.rotations.push(random_quaternion(rng));
    model.opacity_logits.push(opacity_logit);
    model.sh_coefficients.push(sh);
    model.object_ids.push(object_ids);
}

/// `count` random Gaussians in front of `camera` (from [`test_camera`]), 1 to 3 pixels of screen
/// standard deviation up to about 8, opacities between 0.2 and 0.95, object ids 0..3 per level.
pub fn random_scene(seed: u64, count: usize, camera: &RenderCamera) -> GaussianModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut model = GaussianModel::default();
    for _ in 0..count {
        let z = rng.random_range(1.5..5.0);
        let u = rng.random_range(-4.0..camera.width as f32 + 4.0);
        let v = rng.random_range(-4.0..camera.height as f32 + 4.0);
        let mean = point_at_pixel(camera, u, v, z);
        // Screen sigma ~ fx * scale / z.
        let pixels: f32 = rng.random_range(1.0..5.0);
        let base = (pixels * z / camera.fx).ln();
        let log_scale = std::array::from_fn(|_| base + rng.random_range(-0.7..0.7));
        let opacity_logit = rng.random_range(-1.4..3.0);
        let ids = std::array::from_fn(|_| rng.random_range(0..3));
        push_random(&mut model, &mut rng, mean, log_scale, opacity_logit, ids);
    }
    model
}

/// [`random_scene`] plus one Gaussian of each hard case: behind the camera, centred on a tile
/// corner, needle-thin, very large, nearly transparent, and one straddling the near plane's side.
pub fn edge_case_scene(seed: u64, count: usize, camera: &RenderCamera) -> GaussianModel {
    let mut model = random_scene(seed, count, camera);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let fx = camera.fx;
    let log_pixels = |pixels: f32, z: f32| (pixels * z / fx).ln();
    let none = [OBJECT_NONE; 3];
    // Behind the camera.
    push_random(&mut model, &mut rng, [0.1, 0.0, -1.0], [0.0; 3], 2.0, none);
    // On the corner of tiles (16, 16).
    let corner = point_at_pixel(camera, 16.0, 16.0, 2.5);
    push_random(
        &mut model,
        &mut rng,
        corner,
        [log_pixels(3.0, 2.5); 3],
        1.0,
        none,
    );
    // Needle-thin along one axis.
    let thin = point_at_pixel(camera, 10.0, 23.0, 3.0);
    let thin_scale = [
        log_pixels(0.02, 3.0),
        log_pixels(8.0, 3.0),
        log_pixels(0.02, 3.0),
    ];
    push_random(&mut model, &mut rng, thin, thin_scale, 0.5, none);
    // Very large: covers most of the image.
    let large = point_at_pixel(
        camera,
        camera.width as f32 * 0.6,
        camera.height as f32 * 0.4,
        4.0,
    );
    push_random(
        &mut model,
        &mut rng,
        large,
        [log_pixels(18.0, 4.0); 3],
        -1.0,
        none,
    );
    // Nearly transparent (opacity ~0.007: only the core passes the 1/255 cut).
    let faint = point_at_pixel(camera, 30.0, 12.0, 2.0);
    push_random(
        &mut model,
        &mut rng,
        faint,
        [log_pixels(4.0, 2.0); 3],
        -5.0,
        none,
    );
    // Off to the side near the camera: the frustum clamp of the Jacobian is active.
    push_random(
        &mut model,
        &mut rng,
        [0.4, 0.05, 0.5],
        [log_pixels(8.0, 0.5); 3],
        0.5,
        none,
    );
    model
}

/// Two separated objects (ids 1 and 2 at every level) for object-filter tests: `count` Gaussians
/// each, object 1 in the left half of the image, object 2 in the right half.
pub fn two_object_scene(seed: u64, count: usize, camera: &RenderCamera) -> GaussianModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut model = GaussianModel::default();
    let width = camera.width as f32;
    for object in [1u32, 2] {
        let (u_min, u_max) = if object == 1 {
            (0.1 * width, 0.35 * width)
        } else {
            (0.65 * width, 0.9 * width)
        };
        for _ in 0..count {
            let z = rng.random_range(2.0..4.0);
            let u = rng.random_range(u_min..u_max);
            let v = rng.random_range(0.2 * camera.height as f32..0.8 * camera.height as f32);
            let mean = point_at_pixel(camera, u, v, z);
            let log_scale = [(1.5 * z / camera.fx).ln(); 3];
            push_random(&mut model, &mut rng, mean, log_scale, 2.0, [object; 3]);
        }
    }
    model
}

/// Camera looking at the scene from behind so everything is culled: the same camera turned around.
pub fn turned_around(camera: &RenderCamera) -> RenderCamera {
    RenderCamera {
        camera_from_world: Mat4::from_rotation_y(std::f32::consts::PI) * camera.camera_from_world,
        ..*camera
    }
}
