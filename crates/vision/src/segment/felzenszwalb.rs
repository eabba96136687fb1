//! Felzenszwalb-Huttenlocher graph segmentation ("Efficient Graph-Based Image Segmentation",
//! IJCV 2004), as in the authors' reference code: Gaussian smoothing, an 8-connected pixel graph
//! weighted by RGB distance, Kruskal-order merging while the edge is no heavier than both
//! components' internal difference plus `k / size`, then components under a minimum size merged
//! into a neighbour along the lightest edges. Deterministic: edges are sorted stably.

use image::RgbImage;

/// Union-find with component sizes and FH's merge thresholds.
struct Components {
    parent: Vec<u32>,
    rank: Vec<u8>,
    size: Vec<u64>,
}

impl Components {
    fn new(count: usize) -> Self {
        Components {
            parent: (0..count as u32).collect(),
            rank: vec![0; count],
            size: vec![1; count],
        }
    }

    fn find(&mut self, element: u32) -> u32 {
        let mut root = element;
        while self.parent[root as usize] != root {
            root = self.parent[root as usize];
        }
        // Path compression.
        let mut current = element;
        while self.parent[current as usize] != root {
            let next = self.parent[current as usize];
            self.parent[current as usize] = root;
            current = next;
        }
        root
    }

    /// Joins two roots; returns the new root.
    fn join(&mut self, a: u32, b: u32) -> u32 {
        let (a_index, b_index) = (a as usize, b as usize);
        let (root, child) = if self.rank[a_index] >= self.rank[b_index] {
            (a, b)
        } else {
            (b, a)
        };
        if self.rank[a_index] == self.rank[b_index] {
            self.rank[root as usize] += 1;
        }
        self.parent[child as usize] = root;
        self.size[root as usize] += self.size[child as usize];
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

struct Edge {
    weight: f32,
    a: u32,
    b: u32,
}

/// Segments `image`; returns one region label per pixel (row-major), labels `0..count` numbered
/// in scan order of first appearance, and `count`.
pub fn felzenszwalb(image: &RgbImage, sigma: f32, k: f32, min_size: u64) -> (Vec<u32>, usize) {
    let (width, height) = (image.width() as usize, image.height() as usize);
    let pixel_count = width * height;
    if pixel_count == 0 {
        return (Vec::new(), 0);
    }
    let smoothed = smooth(image, sigma);
    let distance = |a: usize, b: usize| {
        let (p, q) = (smoothed[a], smoothed[b]);
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    };
    let mut edges = Vec::with_capacity(pixel_count * 4);
    for y in 0..height {
        for x in 0..width {
            let here = y * width + x;
            let mut push = |there: usize| {
                edges.push(Edge {
                    weight: distance(here, there),
                    a: here as u32,
                    b: there as u32,
                })
            };
            if x + 1 < width {
                push(here + 1);
            }
            if y + 1 < height {
                push(here + width);
            }
            if x + 1 < width && y + 1 < height {
                push(here + width + 1);
            }
            if x + 1 < width && y > 0 {
                push(here - width + 1);
            }
        }
    }
    edges.sort_by(|first, second| first.weight.total_cmp(&second.weight));

    let mut components = Components::new(pixel_count);
    let mut threshold = vec![k; pixel_count];
    for edge in &edges {
        let a = components.find(edge.a);
        let b = components.find(edge.b);
        if a != b && edge.weight <= threshold[a as usize] && edge.weight <= threshold[b as usize] {
            let root = components.join(a, b);
            threshold[root as usize] = edge.weight + k / components.size[root as usize] as f32;
        }
    }
    for edge in &edges {
        let a = components.find(edge.a);
        let b = components.find(edge.b);
        if a != b
            && (components.size[a as usize] < min_size || components.size[b as usize] < min_size)
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

#[cfg(test)]
mod tests {
    use super::*;

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
