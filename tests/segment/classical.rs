//! The classical fallback segmenter on synthetic images: flat shapes on a flat background, one
//! small disc nested in a rectangle.

use image::{Rgb, RgbImage};
use segsplat_scene::Level;
use segsplat_vision::segment::{BitMask, ClassicalConfig, MaskGenerator, classical_masks};

const WIDTH: u32 = 200;
const HEIGHT: u32 = 150;

enum Shape {
    Rectangle { x0: u32, y0: u32, x1: u32, y1: u32 },
    Disc { cx: f32, cy: f32, radius: f32 },
}

impl Shape {
    fn contains(&self, x: u32, y: u32) -> bool {
        match *self {
            Shape::Rectangle { x0, y0, x1, y1 } => (x0..x1).contains(&x) && (y0..y1).contains(&y),
            Shape::Disc { cx, cy, radius } => {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                dx * dx + dy * dy <= radius * radius
            }
        }
    }

    fn mask(&self) -> BitMask {
        let mut mask = BitMask::new(WIDTH, HEIGHT);
        for y in 0..HEIGHT {
            for x in 0..WIDTH {
                mask.set(x, y, self.contains(x, y));
            }
        }
        mask
    }
}

const RECTANGLE: Shape = Shape::Rectangle {
    x0: 20,
    y0: 20,
    x1: 110,
    y1: 100,
};
/// Inside the rectangle.
const NESTED_DISC: Shape = Shape::Disc {
    cx: 50.0,
    cy: 50.0,
    radius: 10.0,
};
const BIG_DISC: Shape = Shape::Disc {
    cx: 155.0,
    cy: 60.0,
    radius: 30.0,
};
const LONE_DISC: Shape = Shape::Disc {
    cx: 160.0,
    cy: 125.0,
    radius: 12.0,
};

fn synthetic_image() -> RgbImage {
    let shapes = [
        (&RECTANGLE, [200, 50, 50]),
        (&NESTED_DISC, [40, 90, 200]),
        (&BIG_DISC, [50, 170, 60]),
        (&LONE_DISC, [230, 200, 40]),
    ];
    RgbImage::from_fn(WIDTH, HEIGHT, |x, y| {
        // Later shapes are drawn on top.
        let colour = shapes
            .iter()
            .rev()
            .find(|(shape, _)| shape.contains(x, y))
            .map_or([235, 235, 235], |(_, colour)| *colour);
        Rgb(colour)
    })
}

/// Flat synthetic shapes need no smoothing; with the default sigma 0.8 the blended one-to-three
/// pixel bands along edges are partly kept as regions of their own (see docs/segment.md).
fn flat_image_config() -> ClassicalConfig {
    ClassicalConfig {
        sigma: 0.0,
        ..ClassicalConfig::default()
    }
}

fn best_iou(masks: &[segsplat_vision::segment::ScoredMask], truth: &BitMask) -> f32 {
    masks
        .iter()
        .map(|scored| scored.mask.iou(truth).unwrap_or(0.0))
        .fold(0.0, f32::max)
}

fn rectangle_without_disc() -> BitMask {
    let mut mask = RECTANGLE.mask();
    let disc = NESTED_DISC.mask();
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            if disc.get(x, y) {
                mask.set(x, y, false);
            }
        }
    }
    mask
}

#[test]
fn small_level_separates_the_nested_disc_and_large_level_folds_it_in() {
    let frame = classical_masks(&synthetic_image(), &flat_image_config()).expect("segments");
    let small = frame.level(Level::Small);
    let large = frame.level(Level::Large);

    // Small: every shape on its own, the rectangle with a hole where the disc is.
    assert!(
        best_iou(small, &NESTED_DISC.mask()) > 0.85,
        "nested disc at small"
    );
    assert!(
        best_iou(small, &rectangle_without_disc()) > 0.9,
        "rectangle at small"
    );
    assert!(best_iou(small, &BIG_DISC.mask()) > 0.9, "big disc at small");
    assert!(
        best_iou(small, &LONE_DISC.mask()) > 0.85,
        "lone disc at small"
    );

    // Large: the rectangle is whole (disc included), the disc is no object of its own.
    assert!(
        best_iou(large, &RECTANGLE.mask()) > 0.9,
        "whole rectangle at large"
    );
    assert!(
        best_iou(large, &NESTED_DISC.mask()) < 0.2,
        "nested disc folded in"
    );
    assert!(best_iou(large, &BIG_DISC.mask()) > 0.9, "big disc at large");
    assert!(
        best_iou(large, &LONE_DISC.mask()) > 0.85,
        "lone disc at large"
    );
    // Middle: the nested disc is under a quarter of the rectangle, so it is folded in too.
    assert!(best_iou(frame.level(Level::Middle), &RECTANGLE.mask()) > 0.9);

    for level in Level::ALL {
        let masks = frame.level(level);
        // The background (about 70% of the image) is never an object, and regions partition
        // the image: no pixel is in two masks.
        let pixels = u64::from(WIDTH * HEIGHT);
        let covered: u64 = masks.iter().map(|scored| scored.area).sum();
        assert!(covered < pixels / 2, "{level:?}: {covered} pixels covered");
        for (index, first) in masks.iter().enumerate() {
            assert!(first.area < pixels / 2);
            for second in &masks[index + 1..] {
                assert_eq!(first.mask.intersection_area(&second.mask), Ok(0));
            }
        }
        assert!(masks.windows(2).all(|pair| pair[0].area >= pair[1].area));
        assert!(masks.len() <= 6, "{level:?}: {} regions", masks.len());
    }
}

#[test]
fn deterministic_and_resolution_independent_defaults() {
    let image = synthetic_image();
    let config = flat_image_config();
    let first = classical_masks(&image, &config).expect("segments");
    let second = classical_masks(&image, &config).expect("segments");
    assert_eq!(first, second);

    // Twice the resolution: the same objects are found at the large level.
    let doubled = image::imageops::resize(
        &image,
        WIDTH * 2,
        HEIGHT * 2,
        image::imageops::FilterType::Nearest,
    );
    let frame = classical_masks(&doubled, &config).expect("segments");
    assert_eq!(
        frame.level(Level::Large).len(),
        first.level(Level::Large).len()
    );
}

#[test]
fn invalid_config_names_the_field_and_generator_enum_runs() {
    let config = ClassicalConfig {
        max_region_fraction: 1.5,
        ..ClassicalConfig::default()
    };
    let error = classical_masks(&synthetic_image(), &config).expect_err("invalid");
    assert!(error.to_string().contains("max_region_fraction"), "{error}");

    let mut generator = MaskGenerator::Classical(ClassicalConfig::default());
    let frame = generator.generate(&synthetic_image(), 0).expect("segments");
    assert!(!frame.level(Level::Small).is_empty());
}
