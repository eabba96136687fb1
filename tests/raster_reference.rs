//! The CPU reference renderer's backward pass against central finite differences of its forward
//! pass (f64), on random scenes with the hard cases included.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use segsplat_engine::reference::scenes::{edge_case_scene, test_camera, two_object_scene};
use segsplat_engine::reference::{
    ReferenceForward, ReferenceGaussians, parameter_name, render_backward, render_forward,
};
use segsplat_engine::{ObjectFilter, RenderCamera, RenderSettings, TILE_SIZE};
use segsplat_scene::Level;

fn weighted_loss(forward: &ReferenceForward, weights: &[[f64; 4]]) -> f64 {
    forward
        .image
        .iter()
        .zip(weights)
        .map(|(pixel, w)| (0..4).map(|c| pixel[c] * w[c]).sum::<f64>())
        .sum()
}

fn random_weights(seed: u64, pixels: usize) -> Vec<[f64; 4]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..pixels)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect()
}

/// Central difference of the weighted loss along one parameter. The step shrinks when the two
/// evaluations composite different fragment sets (a fragment crossed the 1/255 or transmittance
/// threshold: the loss jumps there and no derivative exists).
fn finite_difference(
    gaussians: &ReferenceGaussians,
    index: usize,
    slot: usize,
    camera: &RenderCamera,
    settings: &RenderSettings,
    weights: &[[f64; 4]],
) -> Option<f64> {
    let mut eps = 1e-5;
    for _ in 0..4 {
        let mut plus = gaussians.clone();
        *plus.parameters_mut(index)[slot] += eps;
        let mut minus = gaussians.clone();
        *minus.parameters_mut(index)[slot] -= eps;
        let forward_plus = render_forward(&plus, camera, settings);
        let forward_minus = render_forward(&minus, camera, settings);
        if forward_plus.contributors == forward_minus.contributors {
            let difference =
                weighted_loss(&forward_plus, weights) - weighted_loss(&forward_minus, weights);
            return Some(difference / (2.0 * eps));
        }
        eps *= 0.01;
    }
    None
}

fn check_gradients(seed: u64, settings: RenderSettings) {
    let camera = test_camera(40, 36);
    let model = edge_case_scene(seed, 6, &camera);
    let gaussians = ReferenceGaussians::from_model(&model);
    let weights = random_weights(seed + 100, camera.pixel_count());
    let forward = render_forward(&gaussians, &camera, &settings);
    assert!(
        forward.image.iter().any(|p| p[3] > 0.5),
        "scene renders something"
    );
    let grads = render_backward(&gaussians, &forward, &weights);
    let mut checked = 0;
    let mut worst = 0.0f64;
    for index in 0..gaussians.len() {
        let analytic = grads.parameters.parameters(index);
        for (slot, &analytic) in analytic.iter().enumerate() {
            let Some(numeric) =
                finite_difference(&gaussians, index, slot, &camera, &settings, &weights)
            else {
                continue;
            };
            let error = (numeric - analytic).abs();
            let tolerance = 1e-4 + 1e-4 * numeric.abs().max(analytic.abs());
            worst = worst.max(error / (1.0 + numeric.abs()));
            assert!(
                error <= tolerance,
                "seed {seed} gaussian {index} {}: analytic {analytic} vs numeric {numeric}",
                parameter_name(slot)
            );
            checked += 1;
        }
    }
    println!("seed {seed}: {checked} derivatives checked, worst relative error {worst:e}");
    assert!(checked > 100);
}

#[test]
fn reference_gradients_match_finite_differences() {
    check_gradients(
        1,
        RenderSettings {
            background: [0.2, 0.5, 0.9],
            ..RenderSettings::default()
        },
    );
}

#[test]
fn reference_gradients_match_finite_differences_low_sh_degree() {
    check_gradients(
        2,
        RenderSettings {
            sh_degree: 1,
            ..RenderSettings::default()
        },
    );
}

#[test]
fn reference_object_filter_renders_only_that_object() {
    let camera = test_camera(48, 32);
    let gaussians = ReferenceGaussians::from_model(&two_object_scene(3, 5, &camera));
    let only = |id| RenderSettings {
        filter: ObjectFilter::Object {
            level: Level::Middle,
            id,
        },
        ..RenderSettings::default()
    };
    let left = render_forward(&gaussians, &camera, &only(1));
    let right = render_forward(&gaussians, &camera, &only(2));
    let alpha_sum = |forward: &ReferenceForward, columns: std::ops::Range<u32>| -> f64 {
        (0..camera.height)
            .flat_map(|y| {
                columns
                    .clone()
                    .map(move |x| (y * camera.width + x) as usize)
            })
            .map(|i| forward.image[i][3])
            .sum()
    };
    assert!(alpha_sum(&left, 0..20) > 10.0);
    assert!(alpha_sum(&left, 28..48) < 1e-9);
    assert!(alpha_sum(&right, 28..48) > 10.0);
    assert!(alpha_sum(&right, 0..20) < 1e-9);
}

#[test]
fn edge_case_scene_exercises_every_case() {
    let camera = test_camera(40, 36);
    let gaussians = ReferenceGaussians::from_model(&edge_case_scene(1, 6, &camera));
    let forward = render_forward(&gaussians, &camera, &RenderSettings::default());
    let n = gaussians.len();
    let contributes = |index: usize| {
        forward
            .contributors
            .iter()
            .any(|list| list.contains(&(index as u32)))
    };
    // Order of edge cases: behind, tile corner, thin, large, faint, side (frustum clamp).
    assert!(
        forward.projected[n - 6].is_none(),
        "behind the camera is culled"
    );
    forward.projected[n - 5].expect("corner splat visible");
    let tile = TILE_SIZE;
    for (x, y) in [
        (tile - 1, tile - 1),
        (tile, tile - 1),
        (tile - 1, tile),
        (tile, tile),
    ] {
        let pixel = (y * camera.width + x) as usize;
        assert!(
            forward.contributors[pixel].contains(&((n - 5) as u32)),
            "the corner splat reaches pixel ({x}, {y}) of each tile around the corner"
        );
    }
    let thin = forward.projected[n - 4].expect("thin splat visible");
    let [a, b, c] = thin.conic;
    let (trace, det) = (a + c, a * c - b * b);
    let eigen_ratio =
        (trace + (trace * trace - 4.0 * det).sqrt()) / (trace - (trace * trace - 4.0 * det).sqrt());
    assert!(
        eigen_ratio > 10.0,
        "thin splat is anisotropic: {eigen_ratio}"
    );
    let large = forward.projected[n - 3].expect("large splat visible");
    assert!(large.radius > 40.0);
    let faint = forward.projected[n - 2].expect("faint splat projected");
    assert!(faint.opacity < 0.01);
    let side = forward.projected[n - 1].expect("side splat visible");
    assert!(
        side.mean2d.x > camera.width as f64,
        "centre off screen, footprint on screen"
    );
    for index in n - 5..n {
        assert!(
            contributes(index),
            "edge case {index} contributes to some pixel"
        );
    }
}
