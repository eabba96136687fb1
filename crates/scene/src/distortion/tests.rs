use image::Rgb32FImage;

use super::*;
use crate::InstanceMask;

fn intrinsics(model: &str, distortion: &[f64]) -> Intrinsics {
    Intrinsics {
        width: 64,
        height: 48,
        fx: 50.0,
        fy: 52.0,
        cx: 31.0,
        cy: 25.0,
        model: model.to_string(),
        distortion: distortion.to_vec(),
    }
}

fn lens(model: &str, distortion: &[f64]) -> Lens {
    Lens::from_intrinsics(&intrinsics(model, distortion)).unwrap()
}

fn assert_close(actual: [f64; 2], expected: [f64; 2], tolerance: f64) {
    let error = (actual[0] - expected[0])
        .abs()
        .max((actual[1] - expected[1]).abs());
    assert!(
        error <= tolerance,
        "{actual:?} vs {expected:?}: {error:e} > {tolerance:e}"
    );
}

#[test]
fn known_values() {
    // OPENCV, worked by hand: r² = 0.13, radial = 1 + 0.1 r² + 0.01 r⁴ = 1.013169.
    let opencv = lens("OPENCV", &[0.1, 0.01, 0.001, 0.002]);
    assert_close(
        opencv.distort([0.3, -0.2]),
        [
            0.3 * 1.013169 + 2.0 * 0.001 * 0.3 * -0.2 + 0.002 * (0.13 + 2.0 * 0.09),
            -0.2 * 1.013169 + 2.0 * 0.002 * 0.3 * -0.2 + 0.001 * (0.13 + 2.0 * 0.04),
        ],
        1e-12,
    );
    // SIMPLE_RADIAL at r² = 0.25: factor 1 + 0.25 k.
    assert_close(
        lens("SIMPLE_RADIAL", &[-0.2]).distort([0.3, 0.4]),
        [0.3 * 0.95, 0.4 * 0.95],
        1e-12,
    );
    // RADIAL: 1 + k1 r² + k2 r⁴ at r² = 0.25.
    assert_close(
        lens("RADIAL", &[0.1, -0.04]).distort([0.3, 0.4]),
        [0.3 * 1.0225, 0.4 * 1.0225],
        1e-12,
    );
    // FULL_OPENCV's rational radial term: (1 + 0.1 + 0.01 + 0.001) / (1 + 0.2 + 0.02 + 0.002)
    // at r² = 1 (no tangential terms).
    assert_close(
        lens(
            "FULL_OPENCV",
            &[0.1, 0.01, 0.0, 0.0, 0.001, 0.2, 0.02, 0.002],
        )
        .distort([0.6, 0.8]),
        [0.6 * 1.111 / 1.222, 0.8 * 1.111 / 1.222],
        1e-12,
    );
    // OPENCV_FISHEYE on the x axis: x_d = θ (1 + k1 θ²), θ = atan 0.5.
    let theta = 0.5f64.atan();
    assert_close(
        lens("OPENCV_FISHEYE", &[0.1, 0.0, 0.0, 0.0]).distort([0.5, 0.0]),
        [theta * (1.0 + 0.1 * theta * theta), 0.0],
        1e-12,
    );
    // FOV: r_d = atan(2 r tan(ω/2)) / ω.
    let omega = 0.9f64;
    assert_close(
        lens("FOV", &[omega]).distort([0.5, 0.0]),
        [(2.0 * 0.5 * (omega / 2.0).tan()).atan() / omega, 0.0],
        1e-12,
    );
}

#[test]
fn zero_coefficients_are_the_identity() {
    for (model, count) in [
        ("PINHOLE", 0),
        ("SIMPLE_RADIAL", 1),
        ("RADIAL", 2),
        ("OPENCV", 4),
        ("FULL_OPENCV", 8),
        ("FOV", 1),
    ] {
        let lens = lens(model, &vec![0.0; count]);
        assert!(lens.is_pinhole(), "{model}");
        for point in [[0.0, 0.0], [0.3, -0.7], [-1.2, 0.9]] {
            assert_eq!(lens.distort(point), point, "{model}");
        }
    }
    // A fisheye with zero coefficients is the equidistant projection, not a pinhole.
    let fisheye = lens("OPENCV_FISHEYE", &[0.0; 4]);
    assert!(!fisheye.is_pinhole());
    assert_close(
        fisheye.distort([1.0, 0.0]),
        [std::f64::consts::FRAC_PI_4, 0.0],
        1e-12,
    );
    let image = Rgb32FImage::from_fn(8, 6, |x, y| image::Rgb([x as f32, y as f32, 0.5]));
    let camera = intrinsics("OPENCV", &[0.0; 4]);
    let (same, stats) = undistort_rgb(&image, &camera, &Lens::from_intrinsics(&camera).unwrap());
    assert_eq!(same, image);
    assert_eq!(stats.outside_fraction, 0.0);
}

#[test]
fn distorted_points_undistort_back() {
    let lenses = [
        lens("SIMPLE_RADIAL", &[-0.12]),
        lens("RADIAL", &[0.08, -0.01]),
        lens("OPENCV", &[-0.28, 0.09, 0.0012, -0.0009]),
        lens("OPENCV", &[0.12, 0.03, -0.002, 0.001]),
        lens(
            "FULL_OPENCV",
            &[0.2, -0.05, 0.001, 0.002, 0.01, 0.1, -0.02, 0.003],
        ),
        lens("OPENCV_FISHEYE", &[0.05, -0.01, 0.002, -0.0003]),
        lens("SIMPLE_RADIAL_FISHEYE", &[0.03]),
        lens("RADIAL_FISHEYE", &[0.03, -0.004]),
        lens("FOV", &[0.8]),
    ];
    for lens in &lenses {
        for i in -6..=6 {
            for j in -4..=4 {
                let point = [f64::from(i) * 0.1, f64::from(j) * 0.1];
                let distorted = lens.distort(point);
                let back = lens.undistort(distorted).expect("converges");
                assert_close(back, point, 1e-9);
            }
        }
    }
    let camera = intrinsics("OPENCV", &[-0.28, 0.09, 0.0012, -0.0009]);
    let opencv = Lens::from_intrinsics(&camera).unwrap();
    let pixel = [5.5, 40.25];
    let distorted = distort_pixel(&camera, &opencv, pixel);
    assert!((distorted[0] - pixel[0]).abs() > 1.0);
    assert_close(
        undistort_pixel(&camera, &opencv, distorted).unwrap(),
        pixel,
        1e-6,
    );
}

#[test]
fn bad_cameras_are_refused_with_the_reason() {
    let error = |model: &str, distortion: &[f64]| {
        Lens::from_intrinsics(&intrinsics(model, distortion)).unwrap_err()
    };
    assert!(error("THIN_PRISM_FISHEYE", &[0.0; 8]).contains("THIN_PRISM_FISHEYE cannot be"));
    assert!(error("KANNALA", &[]).contains("unknown camera model \"KANNALA\""));
    let nan = error("OPENCV", &[0.1, f64::NAN, 0.0, 0.0]);
    assert!(nan.contains("parameter 2 (k2) is NaN"), "{nan}");
    assert!(error("OPENCV", &[0.1]).contains("expected 4 distortion parameters, found 1"));
    let mut infinite = intrinsics("PINHOLE", &[]);
    infinite.fx = f64::INFINITY;
    assert!(
        Lens::from_intrinsics(&infinite)
            .unwrap_err()
            .contains("fx is inf")
    );
    infinite.fx = -3.0;
    assert!(
        Lens::from_intrinsics(&infinite)
            .unwrap_err()
            .contains("positive")
    );
}

#[test]
fn masks_keep_their_labels() {
    // Vertical stripes of ids 0, 7, 300 under strong barrel distortion.
    let camera = intrinsics("OPENCV", &[-0.3, 0.1, 0.002, -0.001]);
    let lens = Lens::from_intrinsics(&camera).unwrap();
    let (width, height) = (camera.width, camera.height);
    let ids: Vec<u32> = (0..height)
        .flat_map(|_| (0..width).map(|x| [0, 7, 300][(x / 22) as usize]))
        .collect();
    let mask = InstanceMask { width, height, ids };
    let (undistorted, stats) = undistort_mask(&mask, &camera, &lens);
    assert_eq!(
        stats.outside_fraction, 0.0,
        "barrel: every source is inside"
    );
    assert!(undistorted.ids.iter().all(|id| [0, 7, 300].contains(id)));
    assert_ne!(undistorted.ids, mask.ids);
    // Each output pixel has the id of the input pixel nearest its distorted position.
    for (index, id) in undistorted.ids.iter().enumerate() {
        let (x, y) = (index as u32 % width, index as u32 / width);
        let [u, v] = distort_pixel(&camera, &lens, [f64::from(x) + 0.5, f64::from(y) + 0.5]);
        let source_x = (u.floor() as u32).min(width - 1);
        let source_y = (v.floor() as u32).min(height - 1);
        assert_eq!(*id, mask.ids[(source_y * width + source_x) as usize]);
    }
}

mod cost {
    use super::*;

    /// The cost of undistorting one phone frame (1080x1920, OPENCV) at load; run with
    /// `cargo test -p segsplat-scene --lib distortion::tests::cost -- --ignored --nocapture`.
    #[test]
    #[ignore = "timing, prints the cost"]
    fn undistort_a_1080x1920_frame() {
        let camera = Intrinsics {
            width: 1080,
            height: 1920,
            fx: 1450.0,
            fy: 1450.0,
            cx: 540.0,
            cy: 960.0,
            model: "OPENCV".to_string(),
            distortion: vec![0.08, -0.15, 0.001, -0.0005],
        };
        let lens = Lens::from_intrinsics(&camera).unwrap();
        let image = Rgb32FImage::from_fn(1080, 1920, |x, y| {
            image::Rgb([(x % 7) as f32 / 7.0, (y % 5) as f32 / 5.0, 0.5])
        });
        let mask = InstanceMask {
            width: 1080,
            height: 1920,
            ids: (0..1080 * 1920).map(|i| (i % 13) as u32).collect(),
        };
        for _ in 0..2 {
            let start = std::time::Instant::now();
            let (_, stats) = undistort_rgb(&image, &camera, &lens);
            let rgb = start.elapsed();
            let start = std::time::Instant::now();
            undistort_mask(&mask, &camera, &lens);
            let ids = start.elapsed();
            println!(
                "1080x1920 OPENCV on {} threads: image {rgb:?}, mask {ids:?}, {:.2}% from outside",
                rayon::current_num_threads(),
                stats.outside_fraction * 100.0
            );
        }
    }
}
