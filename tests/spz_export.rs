//! SPZ export read back by a reader the project did not write (`spz_rs`, a translation of
//! Niantic's reference loader): every attribute within its quantisation step, and renders of the
//! decoded Gaussians against renders of the originals.
//!
//! With `SEGSPLAT_SPZ_PLY=path/scene.ply` (and optionally `SEGSPLAT_SPZ_DATASET=dataset` for its
//! cameras) the second test also measures a real trained scene and prints the size ratio and PSNR
//! (docs/benchmarks.md).

use segsplat_engine::image_metrics::psnr;
use segsplat_engine::ply::{read_ply, write_ply};
use segsplat_engine::reference::scenes::{random_scene, test_camera};
use segsplat_engine::render::Renderer;
use segsplat_engine::spz::{SH_SIGN_RDF_TO_RUB, SPZ_MAGIC, write_spz};
use segsplat_engine::{GaussianModel, GpuGaussians, RenderCamera, RenderSettings};
use segsplat_gpu::GpuContext;

mod gpu_support;
use gpu_support::gpu_context;

/// The SPZ bytes decoded by `spz_rs` into our model, RUB axes turned back to RDF.
fn decode_with_spz_rs(bytes: &[u8], ids_from: &GaussianModel) -> GaussianModel {
    let packed = spz_rs::load_packed_gaussians_from_spz_buffer(bytes).expect("spz_rs reads it");
    assert_eq!(packed.num_points, ids_from.len());
    let mut model = GaussianModel::default();
    for index in 0..packed.num_points {
        let gaussian = packed.unpack(index);
        let [x, y, z] = gaussian.position;
        model.means.push([x, -y, -z]);
        model.log_scales.push(gaussian.scale);
        let [w, qx, qy, qz] = gaussian.rotation;
        model.rotations.push([w, qx, -qy, -qz]);
        model.opacity_logits.push(gaussian.alpha);
        let mut sh = [[0.0f32; 3]; 16];
        sh[0] = gaussian.color;
        for k in 0..15 {
            // Each sign is its own inverse: the same table turns RUB back into RDF.
            let sign = SH_SIGN_RDF_TO_RUB[k];
            sh[k + 1] = [
                gaussian.sh_r[k] * sign,
                gaussian.sh_g[k] * sign,
                gaussian.sh_b[k] * sign,
            ];
        }
        model.sh_coefficients.push(sh);
        model.object_ids.push(ids_from.object_ids[index]);
    }
    model
}

fn render(ctx: &GpuContext, model: &GaussianModel, camera: &RenderCamera) -> Vec<[f32; 3]> {
    let gaussians = GpuGaussians::upload(ctx, model, model.len()).unwrap();
    let mut renderer = Renderer::new(ctx).unwrap();
    let settings = RenderSettings {
        background: [0.0; 3],
        sh_degree: 3,
        ..RenderSettings::default()
    };
    let output = renderer
        .render_checked(ctx, &gaussians, camera, &settings)
        .unwrap();
    output
        .read_image(ctx)
        .unwrap()
        .iter()
        .take(camera.pixel_count())
        .map(|pixel| [pixel[0], pixel[1], pixel[2]])
        .collect()
}

fn sigmoid(logit: f32) -> f32 {
    1.0 / (1.0 + (-logit).exp())
}

#[test]
fn a_foreign_reader_gets_back_what_was_written() {
    let camera = test_camera(96, 72);
    let model = random_scene(3, 600, &camera);
    let mut spz = Vec::new();
    write_spz(&model, 3, &mut spz).unwrap();
    assert_eq!(gunzipped_magic(&spz), SPZ_MAGIC);
    let decoded = decode_with_spz_rs(&spz, &model);
    for index in 0..model.len() {
        for axis in 0..3 {
            let step = 1.0 / 4096.0;
            assert!((decoded.means[index][axis] - model.means[index][axis]).abs() <= step);
            assert!(
                (decoded.log_scales[index][axis] - model.log_scales[index][axis]).abs()
                    <= 1.0 / 32.0 + 1e-6
            );
            let dc =
                decoded.sh_coefficients[index][0][axis] - model.sh_coefficients[index][0][axis];
            assert!(
                dc.abs() <= 0.5 / 255.0 / 0.15 + 1e-5
                    || model.sh_coefficients[index][0][axis].abs() > 3.3
            );
        }
        let opacity = sigmoid(decoded.opacity_logits[index]) - sigmoid(model.opacity_logits[index]);
        assert!(opacity.abs() <= 0.5 / 255.0 + 1e-6, "opacity {index}");
        // Same rotation up to the quaternion's sign.
        let [a, b] = [decoded.rotations[index], model.rotations[index]];
        let norm = b.iter().map(|v| v * v).sum::<f32>().sqrt();
        let dot: f32 = a.iter().zip(&b).map(|(x, y)| x * y / norm).sum();
        assert!(dot.abs() > 0.995, "rotation {index}: {a:?} vs {b:?}");
        for k in 1..16 {
            for channel in 0..3 {
                let error = decoded.sh_coefficients[index][k][channel]
                    - model.sh_coefficients[index][k][channel];
                let step = if k <= 3 { 8.0 } else { 16.0 } / 128.0;
                assert!(
                    error.abs() <= step / 2.0 + 1.0 / 128.0,
                    "sh {index} {k} {channel}: {error}"
                );
            }
        }
    }
    let Some(ctx) = gpu_context() else { return };
    let original = render(ctx, &model, &camera);
    let from_spz = render(ctx, &decoded, &camera);
    let quality = psnr(&from_spz, &original);
    let mut ply = Vec::new();
    write_ply(&model, &mut ply).unwrap();
    println!(
        "random scene: PLY {} bytes, SPZ {} bytes ({:.1}x smaller); render PSNR {quality:.1} dB",
        ply.len(),
        spz.len(),
        ply.len() as f64 / spz.len() as f64
    );
    assert!(quality > 30.0, "PSNR {quality}");
    assert!(ply.len() > 4 * spz.len());
}

/// The first little-endian u32 of the gzip-compressed `bytes`.
fn gunzipped_magic(bytes: &[u8]) -> u32 {
    let mut magic = [0; 4];
    std::io::Read::read_exact(&mut flate2::read::GzDecoder::new(bytes), &mut magic).unwrap();
    u32::from_le_bytes(magic)
}

#[test]
fn a_trained_scene_given_by_path() {
    let Ok(path) = std::env::var("SEGSPLAT_SPZ_PLY") else {
        println!("SEGSPLAT_SPZ_PLY is not set: no trained scene to measure");
        return;
    };
    let Some(ctx) = gpu_context() else { return };
    let ply = std::fs::read(&path).unwrap();
    let imported = read_ply(ply.as_slice()).unwrap();
    let model = imported.model;
    let mut spz = Vec::new();
    write_spz(&model, imported.sh_degree, &mut spz).unwrap();
    let decoded = decode_with_spz_rs(&spz, &model);
    let cameras: Vec<RenderCamera> = match std::env::var("SEGSPLAT_SPZ_DATASET") {
        Ok(dataset) => {
            let scene = segsplat_scene::load_scene(
                std::path::Path::new(&dataset),
                &segsplat_scene::LoadOptions::default(),
            )
            .unwrap();
            scene
                .frames
                .iter()
                .map(|frame| {
                    let longest = frame.intrinsics.width.max(frame.intrinsics.height) as f32;
                    RenderCamera::from_frame(frame, (512.0 / longest).min(1.0)).unwrap()
                })
                .collect()
        }
        Err(_) => vec![test_camera(256, 256)],
    };
    let mut total = 0.0;
    for camera in &cameras {
        total += psnr(&render(ctx, &decoded, camera), &render(ctx, &model, camera));
    }
    println!(
        "{path}: {} Gaussians, SH degree {}; PLY {} bytes, SPZ {} bytes ({:.1}x smaller); \
         renders of the decoded SPZ against the PLY's: mean PSNR {:.1} dB over {} views",
        model.len(),
        imported.sh_degree,
        ply.len(),
        spz.len(),
        ply.len() as f64 / spz.len() as f64,
        total / cameras.len() as f64,
        cameras.len()
    );
}
