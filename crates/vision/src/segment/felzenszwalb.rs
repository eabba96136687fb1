//! Felzenszwalb-Huttenlocher graph segmentation ("Efficient Graph-Based Image Segmentation",
//! IJCV 2004), as in the authors' reference code: Gaussian smoothing, an 8-connected pixel graph
//! weighted by RGB distance, Kruskal-order merging while the edge is no heavier than both
//! components' internal difference plus `k / size`, then components under a minimum size merged
//! into a neighbour along the lightest edges. Deterministic: edges are sorted stably.

use image::RgbImage;

/// A component's size and FH's merge threshold, read only at its root.
#[derive(Clone, Copy)]
struct RootData {
    size: u32,
    threshold: f32,
}

/// Union-find by size with path halving. Which root a join keeps does not change the partition,
/// the sizes or the thresholds FH reads, so the regions are those of the reference code's
/// union by rank. The parents are an array of their own: the walks up the trees are the random
/// reads of a level's time, and four bytes a pixel keep more of them in cache.
struct Components {
    parent: Vec<u32>,
    roots: Vec<RootData>,
}

impl Components {
    fn new(count: usize, threshold: f32) -> Self {
        Components {
            parent: (0..count as u32).collect(),
            roots: vec![RootData { size: 1, threshold }; count],
        }
    }

    fn find(&mut self, element: u32) -> u32 {
        let mut current = element;
        loop {
            let parent = self.parent[current as usize];
            if parent == current {
                return current;
            }
            let grandparent = self.parent[parent as usize];
            self.parent[current as usize] = grandparent;
            current = grandparent;
        }
    }

    fn root(&self, root: u32) -> RootData {
        self.roots[root as usize]
    }

    /// Joins two roots; returns the new root.
    fn join(&mut self, a: u32, b: u32) -> u32 {
        let (a_size, b_size) = (self.roots[a as usize].size, self.roots[b as usize].size);
        let (root, child) = if a_size >= b_size { (a, b) } else { (b, a) };
        self.parent[child as usize] = root;
        self.roots[root as usize].size = a_size + b_size;
        root
    }
}

/// Separable Gaussian blur of each channel (edges replicated), as floats in 0..255.
fn smooth(image: &RgbImage, sigma: f32) -> Vec<[f32; 3]> {
    let (width, height) = (image.width() as usize, image.height() as usize);
    let pixels: Vec<[f32; 3]> = image.pixels().map(|pixel| pixel.0.map(f32::from)).collect();
    if sigma <= 0.0 {
        return pixels;
    }
    let radius = (4.0 * sigma).ceil() as isize;
    let mut kernel: Vec<f32> = (-radius..=radius)
        .map(|offset| (-((offset * offset) as f32) / (2.0 * sigma * sigma)).exp())
        .collect();
    let total: f32 = kernel.iter().sum();
    kernel.iter_mut().for_each(|weight| *weight /= total);

    let blur = |source: &[[f32; 3]], horizontal: bool| -> Vec<[f32; 3]> {
        let mut target = vec![[0.0f32; 3]; source.len()];
        for y in 0..height {
            for x in 0..width {
                let mut sum = [0.0f32; 3];
                for (tap, &weight) in kernel.iter().enumerate() {
                    let offset = tap as isize - radius;
                    let (sx, sy) = if horizontal {
                        (
                            (x as isize + offset).clamp(0, width as isize - 1) as usize,
                            y,
                        )
                    } else {
                        (
                            x,
                            (y as isize + offset).clamp(0, height as isize - 1) as usize,
                        )
                    };
                    let value = source[sy * width + sx];
                    for channel in 0..3 {
                        sum[channel] += weight * value[channel];
                    }
                }
                target[y * width + x] = sum;
            }
        }
        target
    };
    let horizontal = blur(&pixels, true);
    blur(&horizontal, false)
}

/// The 8-connected graph's four edge directions from a pixel: right, down, down-right, up-right.
const DIRECTIONS: u64 = 4;

/// An edge packed in eight bytes: its weight's bits above its slot (`pixel * 4 + direction`).
/// Weights are non-negative, so their bits order as the weights do, and slots grow in scan
/// order: sorting by the upper half alone, stably, keeps equal weights in scan order. Eight
/// bytes instead of a 12-byte struct are a third less memory for the sort to move and for
/// every level to stream.
type PackedEdge = u64;

fn pack(weight: f32, pixel: usize, direction: u64) -> PackedEdge {
    (u64::from(weight.to_bits()) << 32) | (pixel as u64 * DIRECTIONS + direction)
}

/// The most pixels an image may have for its edges' slots to fit in 32 bits.
pub const MAX_PIXELS: u64 = (1 << 32) / DIRECTIONS;

/// The 8-connected graph's edges (right, down, down-right, up-right of each pixel) in scan order,
/// weighted by the RGB distance of the smoothed image.
fn scan_edges(image: &RgbImage, sigma: f32) -> Vec<PackedEdge> {
    let (width, height) = (image.width() as usize, image.height() as usize);
    let pixel_count = width * height;
    let smoothed = smooth(image, sigma);
    let distance = |a: usize, b: usize| {
        let (p, q) = (smoothed[a], smoothed[b]);
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    };
    let mut edges = Vec::with_capacity(pixel_count * DIRECTIONS as usize);
    for y in 0..height {
        for x in 0..width {
            let here = y * width + x;
            if x + 1 < width {
                edges.push(pack(distance(here, here + 1), here, 0));
            }
            if y + 1 < height {
                edges.push(pack(distance(here, here + width), here, 1));
            }
            if x + 1 < width && y + 1 < height {
                edges.push(pack(distance(here, here + width + 1), here, 2));
            }
            if x + 1 < width && y > 0 {
                edges.push(pack(distance(here, here - width + 1), here, 3));
            }
        }
    }
    edges
}

/// The smoothed image's 8-connected pixel graph with its edges in Kruskal order: what every
/// scale `k` segments from. The classical segmenter's three levels share one (the smoothing,
/// the edges and their sort were about half of a level's time at 1000 px).
pub struct PixelGraph {
    pixel_count: usize,
    /// The pixel a slot's direction leads to, less the slot's own pixel.
    neighbour_offset: [u32; DIRECTIONS as usize],
    edges: Vec<PackedEdge>,
}

impl PixelGraph {
    /// The graph of `image`; `None` when it holds more than [`MAX_PIXELS`] pixels.
    pub fn new(image: &RgbImage, sigma: f32) -> Option<Self> {
        let width = image.width();
        if u64::from(width) * u64::from(image.height()) > MAX_PIXELS {
            return None;
        }
        let mut edges = scan_edges(image, sigma);
        // A stable radix sort on the weight: equal weights keep their scan order, as a stable
        // comparison sort would (the reference code's order), so the regions do not depend on
        // the sort used.
        radsort::sort_by_key(&mut edges, |edge| (edge >> 32) as u32);
        Some(PixelGraph {
            pixel_count: image.width() as usize * image.height() as usize,
            // Up-right wraps: `pixel - width + 1` in u32 arithmetic.
            neighbour_offset: [1, width, width + 1, 1u32.wrapping_sub(width)],
            edges,
        })
    }

    /// An edge's weight and its two pixels.
    fn unpack(&self, edge: PackedEdge) -> (f32, u32, u32) {
        let slot = edge as u32;
        let pixel = slot / DIRECTIONS as u32;
        let neighbour =
            pixel.wrapping_add(self.neighbour_offset[(slot % DIRECTIONS as u32) as usize]);
        (f32::from_bits((edge >> 32) as u32), pixel, neighbour)
    }

    /// FH at scale `k`; returns one region label per pixel (row-major), labels `0..count`
    /// numbered in scan order of first appearance, and `count`.
    pub fn segment(&self, k: f32, min_size: u64) -> (Vec<u32>, usize) {
        self.segment_with(k, min_size, true)
    }

    /// [`Self::segment`], looking at every edge in the small-region pass unless
    /// `skip_edges_between_large`.
    fn segment_with(
        &self,
        k: f32,
        min_size: u64,
        skip_edges_between_large: bool,
    ) -> (Vec<u32>, usize) {
        let pixel_count = self.pixel_count;
        let mut components = Components::new(pixel_count, k);
        for &edge in &self.edges {
            let (weight, a, b) = self.unpack(edge);
            let a = components.find(a);
            let b = components.find(b);
            if a != b
                && weight <= components.root(a).threshold
                && weight <= components.root(b).threshold
            {
                let root = components.join(a, b);
                let size = components.root(root).size;
                components.roots[root as usize].threshold = weight + k / size as f32;
            }
        }
        // Components only grow, so an edge between two that already hold `min_size` pixels never
        // joins in this pass: only the edges touching a smaller one are looked at (the same
        // joins in the same order).
        let in_small: Vec<bool> = (0..pixel_count as u32)
            .map(|pixel| {
                let root = components.find(pixel);
                !skip_edges_between_large || u64::from(components.root(root).size) < min_size
            })
            .collect();
        for &edge in &self.edges {
            let (_, a, b) = self.unpack(edge);
            if !in_small[a as usize] && !in_small[b as usize] {
                continue;
            }
            let a = components.find(a);
            let b = components.find(b);
            if a != b
                && (u64::from(components.root(a).size) < min_size
                    || u64::from(components.root(b).size) < min_size)
            {
                components.join(a, b);
            }
        }

        let mut label_from_root = vec![u32::MAX; pixel_count];
        let mut labels = Vec::with_capacity(pixel_count);
        let mut count = 0u32;
        for pixel in 0..pixel_count {
            let root = components.find(pixel as u32) as usize;
            if label_from_root[root] == u32::MAX {
                label_from_root[root] = count;
                count += 1;
            }
            labels.push(label_from_root[root]);
        }
        (labels, count as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn felzenszwalb(image: &RgbImage, sigma: f32, k: f32, min_size: u64) -> (Vec<u32>, usize) {
        PixelGraph::new(image, sigma)
            .expect("a small image")
            .segment(k, min_size)
    }

    /// The radix sort keeps the order of a stable comparison sort, ties included: an image of
    /// few colours unsmoothed has most of its edges at a handful of weights.
    #[test]
    fn edges_are_in_stable_weight_order() {
        let image = RgbImage::from_fn(37, 23, |x, y| {
            let step = ((x * 7 + y * 13) ^ (x * y)) % 4;
            image::Rgb([60 * step as u8, 90, 255 - 50 * step as u8])
        });
        let graph = PixelGraph::new(&image, 0.0).expect("a small image");
        let mut reference: Vec<(f32, u32, u32)> = scan_edges(&image, 0.0)
            .into_iter()
            .map(|edge| graph.unpack(edge))
            .collect();
        reference.sort_by(|first, second| first.0.total_cmp(&second.0));
        let sorted: Vec<(f32, u32, u32)> =
            graph.edges.iter().map(|&edge| graph.unpack(edge)).collect();
        assert_eq!(sorted, reference);
        let distinct: std::collections::BTreeSet<u32> =
            sorted.iter().map(|edge| edge.0.to_bits()).collect();
        assert!(
            distinct.len() < 12 && sorted.len() > 3000,
            "ties: {distinct:?}"
        );
    }

    /// Every packed edge unpacks to the pixel pair the plain scan names: right, down,
    /// down-right and up-right neighbours, none across the image's border.
    #[test]
    fn packed_edges_join_the_eight_connected_neighbours() {
        let (width, height) = (7u32, 5u32);
        let image = RgbImage::from_fn(width, height, |x, y| {
            image::Rgb([x as u8 * 30, y as u8 * 40, 9])
        });
        let graph = PixelGraph::new(&image, 0.0).expect("a small image");
        let mut expected = Vec::new();
        for y in 0..height as i64 {
            for x in 0..width as i64 {
                for (dx, dy) in [(1, 0), (0, 1), (1, 1), (1, -1)] {
                    let (nx, ny) = (x + dx, y + dy);
                    if (0..width as i64).contains(&nx) && (0..height as i64).contains(&ny) {
                        expected.push((
                            (y * width as i64 + x) as u32,
                            (ny * width as i64 + nx) as u32,
                        ));
                    }
                }
            }
        }
        let scanned: Vec<(u32, u32)> = scan_edges(&image, 0.0)
            .into_iter()
            .map(|edge| {
                let (weight, a, b) = graph.unpack(edge);
                let colour = |pixel: u32| image.get_pixel(pixel % width, pixel / width).0;
                let plain = colour(a)
                    .iter()
                    .zip(colour(b))
                    .map(|(p, q)| (f32::from(*p) - f32::from(q)).powi(2))
                    .sum::<f32>()
                    .sqrt();
                assert!(
                    (weight - plain).abs() < 1e-4,
                    "{a}-{b}: {weight} against {plain}"
                );
                (a, b)
            })
            .collect();
        assert_eq!(scanned, expected);
    }

    /// Leaving out the edges between regions already at `min_size` changes no join: on noisy
    /// images, where the pass joins many small regions, the labels equal those of the pass over
    /// every edge.
    #[test]
    fn the_small_region_pass_skips_only_edges_that_never_join() {
        for seed in 0..4u32 {
            let image = RgbImage::from_fn(61, 43, |x, y| {
                let noise = x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503) ^ (seed * 97);
                let noise = noise.wrapping_mul(2_246_822_519);
                let base = if (x / 15 + y / 11) % 2 == 0 { 60 } else { 180 };
                // Speckles on one pixel in eight: regions of a few pixels after the first pass.
                let speckle = if noise & 7 == 0 {
                    (noise >> 24) as u8 / 2
                } else {
                    0
                };
                image::Rgb([base + (noise >> 29) as u8, 100 + speckle, base])
            });
            let graph = PixelGraph::new(&image, 0.5).expect("a small image");
            for (k, min_size) in [(50.0, 20), (300.0, 60), (1000.0, 200)] {
                let plain = graph.segment_with(k, min_size, false);
                assert_eq!(graph.segment(k, min_size), plain, "seed {seed}, k {k}");
                // The pass joined small regions (the speckles) into the cells.
                let before_the_pass = graph.segment(k, 0).1;
                assert!(
                    1 < plain.1 && plain.1 < before_the_pass,
                    "{} {before_the_pass}",
                    plain.1
                );
            }
        }
    }

    #[test]
    fn two_flat_halves_become_two_regions() {
        let image = RgbImage::from_fn(40, 20, |x, _| {
            if x < 20 {
                image::Rgb([200, 30, 30])
            } else {
                image::Rgb([30, 30, 200])
            }
        });
        let (labels, count) = felzenszwalb(&image, 0.8, 50.0, 50);
        assert_eq!(count, 2, "the blurred seam merges into one side");
        assert_ne!(labels[0], labels[39]);
        assert_eq!(labels[0], labels[19 * 40 + 10]);
        // Deterministic.
        assert_eq!(felzenszwalb(&image, 0.8, 50.0, 50).0, labels);
    }

    #[test]
    fn large_k_merges_weak_edges_but_not_strong_ones() {
        let image = RgbImage::from_fn(40, 20, |x, _| match x {
            0..14 => image::Rgb([100, 100, 100]),
            14..27 => image::Rgb([106, 100, 100]),
            _ => image::Rgb([250, 250, 0]),
        });
        let (_, fine) = felzenszwalb(&image, 0.0, 1.0, 1);
        let (labels, coarse) = felzenszwalb(&image, 0.0, 2000.0, 1);
        assert_eq!(fine, 3);
        assert_eq!(coarse, 2);
        assert_eq!(labels[0], labels[20]);
    }
}
