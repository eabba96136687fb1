//! Masks larger than one storage binding allows are rendered in bands of rows
//! (`render_layer_in_bands`): each band is the whole image's camera with its principal point
//! moved, so the stacked bands must equal the image rendered in one pass, for the full scene
//! and for one object alone, with bands that split tiles and bands that do not.

use segsplat_engine::reference::scenes::{random_scene, test_camera};
use segsplat_engine::render::Renderer;
use segsplat_engine::{GpuGaussians, ObjectFilter};
use segsplat_method::segment_then_splat::objects::{
    RenderedLayer, band_rows, render_layer_in_bands,
};
use segsplat_scene::Level;

mod gpu_support;
use gpu_support::gpu_context;

fn assert_same(banded: &RenderedLayer, whole: &RenderedLayer, what: &str) {
    assert_eq!(banded.alpha.len(), whole.alpha.len(), "{what}");
    let mut covered = 0;
    for (index, (a, b)) in banded.alpha.iter().zip(&whole.alpha).enumerate() {
        assert!(
            (a - b).abs() <= 1e-5,
            "{what}: alpha at pixel {index}: {a} vs {b}"
        );
        covered += usize::from(*b > 0.5);
    }
    for (index, (a, b)) in banded.depth.iter().zip(&whole.depth).enumerate() {
        let same = (a.is_infinite() && b.is_infinite()) || (a - b).abs() <= 1e-4 * b.abs().max(1.0);
        assert!(same, "{what}: depth at pixel {index}: {a} vs {b}");
    }
    assert!(
        covered > whole.alpha.len() / 10,
        "{what}: the scene covers too little to test"
    );
}

#[test]
fn bands_stack_to_the_whole_image() {
    let Some(ctx) = gpu_context() else { return };
    let camera = test_camera(96, 80);
    let model = random_scene(7, 400, &camera);
    let gaussians = GpuGaussians::upload(ctx, &model, model.len()).unwrap();
    let mut renderer = Renderer::new(ctx).unwrap();
    let object = ObjectFilter::Object {
        level: Level::Small,
        id: 1,
    };
    for filter in [ObjectFilter::All, object] {
        let whole = render_layer_in_bands(
            ctx,
            &mut renderer,
            &gaussians,
            &camera,
            filter,
            camera.height,
        )
        .unwrap();
        for rows in [16, 7, 1] {
            let banded =
                render_layer_in_bands(ctx, &mut renderer, &gaussians, &camera, filter, rows)
                    .unwrap();
            assert_same(&banded, &whole, &format!("{filter:?} in bands of {rows}"));
        }
    }
}

#[test]
fn band_heights_follow_the_binding_limit() {
    // lavapipe's 128 MiB: a 4096-wide RGBA f32 row is 64 KiB, so 2048 rows fit, but a band is
    // also held to 4 Mi pixels (1024 rows at this width).
    assert_eq!(band_rows(4096, 128 << 20), 1024);
    assert_eq!(band_rows(1000, 1 << 20), 64);
    assert_eq!(band_rows(100, 16 * 100 * 5), 5);
    assert_eq!(band_rows(100_000, 16), 1);
}
