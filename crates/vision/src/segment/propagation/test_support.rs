//! A synthetic sequence for propagation tests, and stand-in segmenters that answer from exact
//! colour regions: discs moving over two static tiles; one disc leaves the frame, one enters.

use image::{Rgb, RgbImage};

use super::{FirstFrameMasks, Propagation, PropagationOptions, propagate_masks};
use crate::segment::{
    AutomaticConfig, BitMask, MaskGenerator, PointMasks, PointPromptSegmenter, PromptError,
    RegionAnswer, RegionPrompt, RegionPromptSegmenter,
};

pub const WIDTH: u32 = 128;
pub const HEIGHT: u32 = 96;
pub const FRAMES: usize = 30;
/// Truth ids of the two tiles (large level only).
pub const TILE_IDS: [u32; 2] = [10, 11];
const TILE_COLOURS: [[u8; 3]; 2] = [[70, 70, 70], [100, 100, 120]];

/// A disc moving at constant velocity from `from_frame` on; its truth id is its index + 1.
pub struct MovingDisc {
    pub colour: [u8; 3],
    pub radius: f32,
    pub start: [f32; 2],
    pub velocity: [f32; 2],
    pub from_frame: usize,
}

impl MovingDisc {
    fn contains(&self, frame: usize, x: u32, y: u32) -> bool {
        if frame < self.from_frame {
            return false;
        }
        let t = (frame - self.from_frame) as f32;
        let centre = [
            self.start[0] + self.velocity[0] * t,
            self.start[1] + self.velocity[1] * t,
        ];
        let (dx, dy) = (x as f32 + 0.5 - centre[0], y as f32 + 0.5 - centre[1]);
        dx * dx + dy * dy <= self.radius * self.radius
    }
}

/// Red crosses the tile border, blue moves left, green leaves on the right by frame 9, yellow
/// enters on the left from frame 12. No two discs ever touch.
pub const DISCS: [MovingDisc; 4] = [
    MovingDisc {
        colour: [220, 40, 40],
        radius: 10.0,
        start: [30.0, 30.0],
        velocity: [2.0, 1.0],
        from_frame: 0,
    },
    MovingDisc {
        colour: [40, 60, 220],
        radius: 9.0,
        start: [100.0, 70.0],
        velocity: [-2.0, 0.0],
        from_frame: 0,
    },
    MovingDisc {
        colour: [40, 200, 60],
        radius: 9.0,
        start: [110.0, 20.0],
        velocity: [3.0, 0.0],
        from_frame: 0,
    },
    MovingDisc {
        colour: [230, 210, 40],
        radius: 10.0,
        start: [-10.0, 18.0],
        velocity: [4.0, 0.0],
        from_frame: 12,
    },
];

/// The disc index at a pixel of a frame, if any.
fn disc_at(frame: usize, x: u32, y: u32) -> Option<usize> {
    DISCS.iter().position(|disc| disc.contains(frame, x, y))
}

fn tile_at(x: u32) -> usize {
    usize::from(x >= WIDTH / 2)
}

pub fn frame_image(frame: usize) -> RgbImage {
    RgbImage::from_fn(WIDTH, HEIGHT, |x, y| match disc_at(frame, x, y) {
        Some(disc) => Rgb(DISCS[disc].colour),
        None => Rgb(TILE_COLOURS[tile_at(x)]),
    })
}

/// True ids per level: discs at every level, the tiles at the large level only.
pub fn truth_ids(frame: usize) -> [Vec<u32>; 3] {
    let mut discs = Vec::with_capacity((WIDTH * HEIGHT) as usize);
    let mut large = Vec::with_capacity(discs.capacity());
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let disc = disc_at(frame, x, y).map(|index| index as u32 + 1);
            discs.push(disc.unwrap_or(0));
            large.push(disc.unwrap_or(TILE_IDS[tile_at(x)]));
        }
    }
    [discs.clone(), discs, large]
}

/// Connected (4-neighbour) regions of identical colour: a label per pixel and each label's area.
fn colour_regions(image: &RgbImage) -> (Vec<usize>, Vec<u64>) {
    let (width, height) = (image.width() as usize, image.height() as usize);
    let mut labels = vec![usize::MAX; width * height];
    let mut areas = Vec::new();
    for start in 0..labels.len() {
        if labels[start] != usize::MAX {
            continue;
        }
        let label = areas.len();
        let colour = image.as_raw()[start * 3..start * 3 + 3].to_vec();
        let mut stack = vec![start];
        labels[start] = label;
        let mut area = 0;
        while let Some(index) = stack.pop() {
            area += 1;
            let (x, y) = (index % width, index / width);
            let neighbours = [
                (x > 0).then(|| index - 1),
                (x + 1 < width).then(|| index + 1),
                (y > 0).then(|| index - width),
                (y + 1 < height).then(|| index + width),
            ];
            for next in neighbours.into_iter().flatten() {
                if labels[next] == usize::MAX
                    && image.as_raw()[next * 3..next * 3 + 3] == colour[..]
                {
                    labels[next] = label;
                    stack.push(next);
                }
            }
        }
        areas.push(area);
    }
    (labels, areas)
}

/// The current image's colour regions.
#[derive(Default)]
struct Regions {
    width: u32,
    height: u32,
    labels: Vec<usize>,
    areas: Vec<u64>,
}

impl Regions {
    fn set(&mut self, image: &RgbImage) {
        (self.labels, self.areas) = colour_regions(image);
        (self.width, self.height) = image.dimensions();
    }

    fn label_at(&self, [x, y]: [f32; 2]) -> Option<usize> {
        let (x, y) = (x.floor(), y.floor());
        let inside = x >= 0.0 && y >= 0.0 && x < self.width as f32 && y < self.height as f32;
        inside.then(|| self.labels[y as usize * self.width as usize + x as usize])
    }

    fn mask(&self, label: usize) -> BitMask {
        let values: Vec<bool> = self.labels.iter().map(|&l| l == label).collect();
        BitMask::from_bools(self.width, self.height, &values).expect("labels cover the image")
    }
}

/// A stand-in region decoder: the colour region under the first positive point, when at least a
/// quarter of it lies in the prompt box (a box on another region answers nothing). It hands back
/// a token prior and counts what it was asked.
#[derive(Default)]
pub struct RegionOracle {
    regions: Regions,
    pub prompts: usize,
    pub prompts_with_prior: usize,
    pub largest_call: usize,
}

impl RegionPromptSegmenter for RegionOracle {
    fn set_image(&mut self, image: &RgbImage) -> Result<(), PromptError> {
        self.regions.set(image);
        Ok(())
    }

    fn predict_regions(
        &mut self,
        prompts: &[RegionPrompt],
    ) -> Result<Vec<RegionAnswer>, PromptError> {
        if self.regions.labels.is_empty() {
            return Err(PromptError::NoImage);
        }
        self.largest_call = self.largest_call.max(prompts.len());
        self.prompts += prompts.len();
        self.prompts_with_prior += prompts.iter().filter(|p| p.mask_input.is_some()).count();
        Ok(prompts.iter().map(|prompt| self.answer(prompt)).collect())
    }
}

impl RegionOracle {
    fn answer(&self, prompt: &RegionPrompt) -> RegionAnswer {
        let regions = &self.regions;
        let label = prompt
            .positive_points
            .first()
            .and_then(|&point| regions.label_at(point));
        let in_box = |label: usize| -> u64 {
            let Some([x0, y0, x1, y1]) = prompt.bounding_box else {
                return regions.areas[label];
            };
            let mut count = 0;
            for y in y0.floor().max(0.0) as u32..(y1.ceil() as u32).min(regions.height) {
                for x in x0.floor().max(0.0) as u32..(x1.ceil() as u32).min(regions.width) {
                    count += u64::from(regions.labels[(y * regions.width + x) as usize] == label);
                }
            }
            count
        };
        match label.filter(|&label| in_box(label) * 4 >= regions.areas[label]) {
            Some(label) => RegionAnswer {
                mask: regions.mask(label),
                predicted_iou: 0.95,
                low_res_logits: Some(vec![label as f32]),
            },
            None => RegionAnswer {
                mask: BitMask::new(regions.width, regions.height),
                predicted_iou: 0.0,
                low_res_logits: None,
            },
        }
    }
}

/// A stand-in point decoder for automatic masks: the colour region under the point, at every
/// level for a disc, at the large level only for a tile (elsewhere nothing, with a low score).
#[derive(Default)]
pub struct PointOracle {
    regions: Regions,
    colours: Vec<[u8; 3]>,
}

impl PointPromptSegmenter for PointOracle {
    fn set_image(&mut self, image: &RgbImage) -> Result<(), PromptError> {
        self.regions.set(image);
        self.colours = vec![[0; 3]; self.regions.areas.len()];
        for (index, &label) in self.regions.labels.iter().enumerate() {
            let rgb = &image.as_raw()[index * 3..index * 3 + 3];
            self.colours[label] = [rgb[0], rgb[1], rgb[2]];
        }
        Ok(())
    }

    fn predict_points(&mut self, points: &[[f32; 2]]) -> Result<Vec<PointMasks>, PromptError> {
        let pixels = (self.regions.width * self.regions.height) as usize;
        Ok(points
            .iter()
            .map(|&point| {
                let label = self.regions.label_at(point);
                let logits: Vec<f32> = self
                    .regions
                    .labels
                    .iter()
                    .map(|&l| if Some(l) == label { 10.0 } else { -10.0 })
                    .collect();
                let tile = label.is_some_and(|label| TILE_COLOURS.contains(&self.colours[label]));
                if tile {
                    PointMasks {
                        logits: [vec![-10.0; pixels], vec![-10.0; pixels], logits],
                        predicted_iou: [0.1, 0.1, 0.95],
                        object_present: true,
                    }
                } else {
                    PointMasks {
                        logits: [logits.clone(), logits.clone(), logits],
                        predicted_iou: [0.95; 3],
                        object_present: true,
                    }
                }
            })
            .collect())
    }
}

/// The id frame 0 gives the right half of the red disc at the small level: a second track of
/// that disc, which propagation must fold into the first.
pub const DUPLICATE_ID: u32 = 7;
pub const PROMPTS_PER_CALL: usize = 4;

pub fn options() -> PropagationOptions {
    PropagationOptions {
        // 100 px at this 128 x 96 sequence (a disc is 250-320 px).
        new_object_min_area_at_full_res: 100.0,
        prompts_per_call: PROMPTS_PER_CALL,
        ..PropagationOptions::default()
    }
}

pub fn first_frame() -> FirstFrameMasks {
    let mut ids = truth_ids(0);
    for (index, id) in ids[0].iter_mut().enumerate() {
        if *id == 1 && index % WIDTH as usize >= 30 {
            *id = DUPLICATE_ID;
        }
    }
    FirstFrameMasks {
        width: WIDTH,
        height: HEIGHT,
        ids,
    }
}

pub fn generator() -> MaskGenerator {
    MaskGenerator::Automatic {
        segmenter: Box::new(PointOracle::default()),
        config: AutomaticConfig {
            points_per_side: 16,
            ..AutomaticConfig::default()
        },
    }
}

pub fn run() -> (Propagation, RegionOracle) {
    let mut oracle = RegionOracle::default();
    let propagation = propagate_masks(
        FRAMES,
        |frame| Ok::<_, std::convert::Infallible>(frame_image(frame)),
        first_frame(),
        &mut oracle,
        &mut generator(),
        &options(),
    )
    .expect("propagation runs");
    (propagation, oracle)
}
