//! The Gaussian scene: a CPU model for I/O and tests, and its struct-of-arrays GPU storage.
//!
//! GPU layout (one storage buffer per parameter group, so Adam can give each group its own learning
//! rate and every binding stays under the adapter's storage-binding limit):
//!
//! | buffer          | f32 per Gaussian | contents                                         |
//! |-----------------|------------------|--------------------------------------------------|
//! | `means`         | 3                | world position                                   |
//! | `log_scales`    | 3                | log of the per-axis standard deviation           |
//! | `rotations`     | 4                | quaternion (w, x, y, z), unnormalised            |
//! | `opacity_logits`| 1                | logit of opacity                                 |
//! | `sh_dc`         | 3                | SH band 0, RGB                                   |
//! | `sh_rest[g]`    | 15               | SH coefficients `1+5g ..= 5+5g`, each RGB        |
//!
//! `sh_rest` is split in three groups of five coefficients because all fifteen higher-band
//! coefficients of two million Gaussians (360 MB) exceed lavapipe's 128 MiB binding limit, while
//! five (120 MB) fit. Object ids live in `object_ids` (3 u32: small, middle, large).
//!
//! Buffers are allocated for a `capacity` and hold `count` live Gaussians, so densification can grow
//! the count in place until the capacity is reached.

use segsplat_gpu::{GpuContext, GpuError};

/// Object id meaning "belongs to no object at this level".
pub const OBJECT_NONE: u32 = u32::MAX;
/// Spherical-harmonic coefficients per colour channel at degree 3.
pub const SH_COEFFICIENTS: usize = 16;
/// Highest supported SH degree.
pub const MAX_SH_DEGREE: u32 = 3;
/// Higher-band coefficients per `sh_rest` buffer.
pub const SH_REST_COEFFICIENTS_PER_GROUP: usize = 5;
/// Number of `sh_rest` buffers.
pub const SH_REST_GROUPS: usize = 3;

#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("Gaussian model field {field} has {found} entries, expected {expected}")]
    LengthMismatch {
        field: &'static str,
        found: usize,
        expected: usize,
    },
    #[error("{count} Gaussians do not fit a GPU scene allocated for {capacity}")]
    OverCapacity { count: usize, capacity: usize },
    // The GPU error is part of the message, not a `source`, so job errors (which keep only the
    // top message) still say which buffer did not fit.
    #[error("scene of {count} Gaussians cannot fit this adapter: {reason}")]
    TooLargeForAdapter { count: usize, reason: GpuError },
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// A Gaussian scene on the CPU (plain arrays, one entry per Gaussian).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaussianModel {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    /// Quaternions (w, x, y, z), normalised where used.
    pub rotations: Vec<[f32; 4]>,
    pub opacity_logits: Vec<f32>,
    /// Per Gaussian, 16 SH coefficients (DC first), each RGB.
    pub sh_coefficients: Vec<[[f32; 3]; SH_COEFFICIENTS]>,
    /// Per Gaussian, object id at each level (small, middle, large); [`OBJECT_NONE`] when none.
    pub object_ids: Vec<[u32; 3]>,
}

impl GaussianModel {
    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Checks that every field has one entry per Gaussian.
    pub fn validate(&self) -> Result<(), ModelError> {
        let expected = self.means.len();
        let lengths = [
            ("log_scales", self.log_scales.len()),
            ("rotations", self.rotations.len()),
            ("opacity_logits", self.opacity_logits.len()),
            ("sh_coefficients", self.sh_coefficients.len()),
            ("object_ids", self.object_ids.len()),
        ];
        for (field, found) in lengths {
            if found != expected {
                return Err(ModelError::LengthMismatch {
                    field,
                    found,
                    expected,
                });
            }
        }
        Ok(())
    }

    /// Appends one Gaussian with only a DC colour (`rgb` is the colour the renderer will show,
    /// i.e. SH DC = (rgb - 0.5) / C0).
    pub fn push_simple(
        &mut self,
        mean: [f32; 3],
        log_scale: [f32; 3],
        rotation: [f32; 4],
        opacity_logit: f32,
        rgb: [f32; 3],
        object_ids: [u32; 3],
    ) {
        let mut sh = [[0.0f32; 3]; SH_COEFFICIENTS];
        sh[0] = rgb.map(|c| (c - 0.5) / SH_C0 as f32);
        self.means.push(mean);
        self.log_scales.push(log_scale);
        self.rotations.push(rotation);
        self.opacity_logits.push(opacity_logit);
        self.sh_coefficients.push(sh);
        self.object_ids.push(object_ids);
    }
}

/// SH band-0 constant.
pub const SH_C0: f64 = 0.282_094_791_773_878_14;

/// The most Gaussians whose largest per-Gaussian buffer (an `sh_rest` group, 15 f32) fits one
/// storage binding of this adapter: 2.2 million on lavapipe's 128 MiB. Capacity headroom is
/// clamped to it, so a scene that fits is never refused for its growth room.
pub fn max_gaussians_for_adapter(ctx: &GpuContext) -> usize {
    max_gaussians_for_binding(ctx.limits.max_storage_buffer_binding_size) as usize
}

/// Most Gaussians whose largest per-Gaussian buffer fits a storage binding of `limit_bytes`
/// (what [`max_gaussians_for_adapter`] computes from an open device; this from a report).
pub fn max_gaussians_for_binding(limit_bytes: u64) -> u64 {
    let largest_bytes_per_gaussian = (SH_REST_COEFFICIENTS_PER_GROUP * 3 * 4) as u64;
    limit_bytes / largest_bytes_per_gaussian
}

/// Creates one per-Gaussian storage buffer after checking it fits one binding.
fn create_per_gaussian(
    ctx: &GpuContext,
    label: &str,
    words_per_gaussian: usize,
    capacity: usize,
) -> Result<wgpu::Buffer, ModelError> {
    // Keep at least one word so empty scenes still bind.
    let bytes = (capacity.max(1) * words_per_gaussian * 4) as u64;
    ctx.storage_buffer(label, bytes)
        .map_err(|reason| ModelError::TooLargeForAdapter {
            count: capacity,
            reason,
        })
}

/// The per-parameter buffers shared by [`GpuGaussians`] and [`GpuGaussianGrads`].
#[derive(Debug)]
pub struct GaussianParameterBuffers {
    pub means: wgpu::Buffer,
    pub log_scales: wgpu::Buffer,
    pub rotations: wgpu::Buffer,
    pub opacity_logits: wgpu::Buffer,
    pub sh_dc: wgpu::Buffer,
    pub sh_rest: [wgpu::Buffer; SH_REST_GROUPS],
}

impl GaussianParameterBuffers {
    pub fn new(ctx: &GpuContext, prefix: &str, capacity: usize) -> Result<Self, ModelError> {
        let rest_words = SH_REST_COEFFICIENTS_PER_GROUP * 3;
        Ok(Self {
            means: create_per_gaussian(ctx, &format!("{prefix}.means"), 3, capacity)?,
            log_scales: create_per_gaussian(ctx, &format!("{prefix}.log_scales"), 3, capacity)?,
            rotations: create_per_gaussian(ctx, &format!("{prefix}.rotations"), 4, capacity)?,
            opacity_logits: create_per_gaussian(
                ctx,
                &format!("{prefix}.opacity_logits"),
                1,
                capacity,
            )?,
            sh_dc: create_per_gaussian(ctx, &format!("{prefix}.sh_dc"), 3, capacity)?,
            sh_rest: [
                create_per_gaussian(ctx, &format!("{prefix}.sh_rest0"), rest_words, capacity)?,
                create_per_gaussian(ctx, &format!("{prefix}.sh_rest1"), rest_words, capacity)?,
                create_per_gaussian(ctx, &format!("{prefix}.sh_rest2"), rest_words, capacity)?,
            ],
        })
    }

    /// All buffers in binding order: means, log_scales, rotations, opacity_logits, sh_dc, sh_rest0..2.
    pub fn all(&self) -> [&wgpu::Buffer; 8] {
        [
            &self.means,
            &self.log_scales,
            &self.rotations,
            &self.opacity_logits,
            &self.sh_dc,
            &self.sh_rest[0],
            &self.sh_rest[1],
            &self.sh_rest[2],
        ]
    }
    /// Writes `model`'s parameters (not its object ids) into the first `model.len()` slots.
    /// Also used for optimiser moments, which share the parameters' layout.
    pub fn write(&self, ctx: &GpuContext, model: &GaussianModel) -> Result<(), ModelError> {
        let host = HostArrays::from_model(model);
        let queue = &ctx.queue;
        queue.write_buffer(&self.means, 0, bytemuck::cast_slice(&host.means));
        queue.write_buffer(&self.log_scales, 0, bytemuck::cast_slice(&host.log_scales));
        queue.write_buffer(&self.rotations, 0, bytemuck::cast_slice(&host.rotations));
        queue.write_buffer(
            &self.opacity_logits,
            0,
            bytemuck::cast_slice(&host.opacity_logits),
        );
        queue.write_buffer(&self.sh_dc, 0, bytemuck::cast_slice(&host.sh_dc));
        for (buffer, words) in self.sh_rest.iter().zip(&host.sh_rest) {
            queue.write_buffer(buffer, 0, bytemuck::cast_slice(words));
        }
        Ok(())
    }

    /// Reads the first `count` entries back as a model-shaped struct (object ids `NONE`).
    pub fn download(&self, ctx: &GpuContext, count: usize) -> Result<GaussianModel, ModelError> {
        let mut model = download_parameters(ctx, self, count)?;
        model.object_ids = vec![[OBJECT_NONE; 3]; count];
        Ok(model)
    }
}

/// Flattened host copies of a model, in the GPU layout.
struct HostArrays {
    means: Vec<f32>,
    log_scales: Vec<f32>,
    rotations: Vec<f32>,
    opacity_logits: Vec<f32>,
    sh_dc: Vec<f32>,
    sh_rest: [Vec<f32>; SH_REST_GROUPS],
}

impl HostArrays {
    fn from_model(model: &GaussianModel) -> Self {
        let mut sh_rest: [Vec<f32>; SH_REST_GROUPS] = Default::default();
        for sh in &model.sh_coefficients {
            for (coefficient, rgb) in sh.iter().enumerate().skip(1) {
                sh_rest[(coefficient - 1) / SH_REST_COEFFICIENTS_PER_GROUP].extend_from_slice(rgb);
            }
        }
        Self {
            means: model.means.iter().flatten().copied().collect(),
            log_scales: model.log_scales.iter().flatten().copied().collect(),
            rotations: model.rotations.iter().flatten().copied().collect(),
            opacity_logits: model.opacity_logits.clone(),
            sh_dc: model.sh_coefficients.iter().flat_map(|sh| sh[0]).collect(),
            sh_rest,
        }
    }
}

/// Reads `count` Gaussians' worth of the parameter buffers back into a model (object ids empty).
fn download_parameters(
    ctx: &GpuContext,
    buffers: &GaussianParameterBuffers,
    count: usize,
) -> Result<GaussianModel, ModelError> {
    let mut words: [Vec<f32>; 8] = Default::default();
    for (target, buffer) in words.iter_mut().zip(buffers.all()) {
        *target = ctx.read_vec(buffer)?;
    }
    Ok(parameters_from_words(&words, count))
}

/// Words per Gaussian in each of [`GaussianParameterBuffers::all`]'s buffers.
pub const PARAMETER_WORDS: [usize; 8] = [
    3,
    3,
    4,
    1,
    3,
    SH_REST_COEFFICIENTS_PER_GROUP * 3,
    SH_REST_COEFFICIENTS_PER_GROUP * 3,
    SH_REST_COEFFICIENTS_PER_GROUP * 3,
];

impl GaussianParameterBuffers {
    /// Each buffer of [`Self::all`] with the bytes its first `count` entries take: what a copy
    /// of `count` Gaussians reads.
    pub fn extents(&self, count: usize) -> [(&wgpu::Buffer, u64); 8] {
        let buffers = self.all();
        std::array::from_fn(|index| (buffers[index], (count * PARAMETER_WORDS[index] * 4) as u64))
    }
}

/// The first `count` Gaussians' parameters (object ids empty) from the words of
/// [`GaussianParameterBuffers::all`]'s buffers, each at least `count` entries long.
pub fn parameters_from_words(words: &[Vec<f32>; 8], count: usize) -> GaussianModel {
    let [
        means,
        log_scales,
        rotations,
        opacity_logits,
        sh_dc,
        rest0,
        rest1,
        rest2,
    ] = words;
    let sh_rest = [rest0, rest1, rest2];
    let rest_words = SH_REST_COEFFICIENTS_PER_GROUP * 3;
    let mut model = GaussianModel::default();
    for i in 0..count {
        model
            .means
            .push([means[3 * i], means[3 * i + 1], means[3 * i + 2]]);
        model.log_scales.push([
            log_scales[3 * i],
            log_scales[3 * i + 1],
            log_scales[3 * i + 2],
        ]);
        model.rotations.push([
            rotations[4 * i],
            rotations[4 * i + 1],
            rotations[4 * i + 2],
            rotations[4 * i + 3],
        ]);
        model.opacity_logits.push(opacity_logits[i]);
        let mut sh = [[0.0f32; 3]; SH_COEFFICIENTS];
        sh[0] = [sh_dc[3 * i], sh_dc[3 * i + 1], sh_dc[3 * i + 2]];
        for (coefficient, rgb) in sh.iter_mut().enumerate().skip(1) {
            let group = (coefficient - 1) / SH_REST_COEFFICIENTS_PER_GROUP;
            let within = (coefficient - 1) % SH_REST_COEFFICIENTS_PER_GROUP;
            let base = i * rest_words + within * 3;
            *rgb = [
                sh_rest[group][base],
                sh_rest[group][base + 1],
                sh_rest[group][base + 2],
            ];
        }
        model.sh_coefficients.push(sh);
    }
    model
}

/// A Gaussian scene in GPU storage.
#[derive(Debug)]
pub struct GpuGaussians {
    pub parameters: GaussianParameterBuffers,
    /// 3 u32 per Gaussian (small, middle, large).
    pub object_ids: wgpu::Buffer,
    count: usize,
    capacity: usize,
}

impl GpuGaussians {
    /// Allocates room for `capacity` Gaussians (checked against the adapter's binding limit) and
    /// uploads `model` (which must fit).
    pub fn upload(
        ctx: &GpuContext,
        model: &GaussianModel,
        capacity: usize,
    ) -> Result<Self, ModelError> {
        model.validate()?;
        if model.len() > capacity {
            return Err(ModelError::OverCapacity {
                count: model.len(),
                capacity,
            });
        }
        let mut gaussians = Self::allocate(ctx, capacity)?;
        gaussians.write(ctx, model)?;
        Ok(gaussians)
    }

    /// Room for `capacity` Gaussians holding none yet: the target a GPU pass fills (the
    /// densification re-layout) before [`Self::set_count`].
    pub fn allocate(ctx: &GpuContext, capacity: usize) -> Result<Self, ModelError> {
        Ok(Self {
            parameters: GaussianParameterBuffers::new(ctx, "gaussians", capacity)?,
            object_ids: create_per_gaussian(ctx, "gaussians.object_ids", 3, capacity)?,
            count: 0,
            capacity,
        })
    }

    /// Declares the first `count` rows live, after a GPU pass wrote them.
    pub fn set_count(&mut self, count: usize) -> Result<(), ModelError> {
        if count > self.capacity {
            return Err(ModelError::OverCapacity {
                count,
                capacity: self.capacity,
            });
        }
        self.count = count;
        Ok(())
    }

    /// Replaces the live Gaussians with `model` (count becomes `model.len()`).
    pub fn write(&mut self, ctx: &GpuContext, model: &GaussianModel) -> Result<(), ModelError> {
        model.validate()?;
        if model.len() > self.capacity {
            return Err(ModelError::OverCapacity {
                count: model.len(),
                capacity: self.capacity,
            });
        }
        self.parameters.write(ctx, model)?;
        let queue = &ctx.queue;
        let ids: Vec<u32> = model.object_ids.iter().flatten().copied().collect();
        queue.write_buffer(&self.object_ids, 0, bytemuck::cast_slice(&ids));
        self.count = model.len();
        Ok(())
    }

    /// Reads the live Gaussians back.
    pub fn download(&self, ctx: &GpuContext) -> Result<GaussianModel, ModelError> {
        let mut model = download_parameters(ctx, &self.parameters, self.count)?;
        let ids: Vec<u32> = ctx.read_vec(&self.object_ids)?;
        model.object_ids = (0..self.count)
            .map(|i| [ids[3 * i], ids[3 * i + 1], ids[3 * i + 2]])
            .collect();
        Ok(model)
    }

    pub fn count(&self) -> usize {
        self.count
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }
}

/// The buffers one render reads: a [`GpuGaussians`] as stored, or with its geometry swapped for
/// a deformed copy (dynamic scenes) while appearance and object ids stay shared.
#[derive(Debug, Clone, Copy)]
pub struct GaussianView<'a> {
    pub means: &'a wgpu::Buffer,
    pub log_scales: &'a wgpu::Buffer,
    pub rotations: &'a wgpu::Buffer,
    pub opacity_logits: &'a wgpu::Buffer,
    pub sh_dc: &'a wgpu::Buffer,
    pub sh_rest: [&'a wgpu::Buffer; SH_REST_GROUPS],
    pub object_ids: &'a wgpu::Buffer,
    pub count: usize,
    pub capacity: usize,
}

impl GpuGaussians {
    pub fn view(&self) -> GaussianView<'_> {
        let p = &self.parameters;
        GaussianView {
            means: &p.means,
            log_scales: &p.log_scales,
            rotations: &p.rotations,
            opacity_logits: &p.opacity_logits,
            sh_dc: &p.sh_dc,
            sh_rest: [&p.sh_rest[0], &p.sh_rest[1], &p.sh_rest[2]],
            object_ids: &self.object_ids,
            count: self.count,
            capacity: self.capacity,
        }
    }
}

impl<'a> From<&'a GpuGaussians> for GaussianView<'a> {
    fn from(gaussians: &'a GpuGaussians) -> Self {
        gaussians.view()
    }
}

impl<'a> From<&'a mut GpuGaussians> for GaussianView<'a> {
    fn from(gaussians: &'a mut GpuGaussians) -> Self {
        gaussians.view()
    }
}

/// Gradients in the same layout as [`GpuGaussians`] (f32), plus the densification statistic.
///
/// Kernels ADD into these buffers; the caller zeroes them once per training step with
/// [`GpuGaussianGrads::encode_zero`], so several renders per step (the object loss) accumulate.
#[derive(Debug)]
pub struct GpuGaussianGrads {
    pub parameters: GaussianParameterBuffers,
    /// 2 f32 per Gaussian: sum over pixels (and renders) of |dL/d mean2d| per screen axis, in
    /// pixels ("absgrad" densification statistic of gsplat / AbsGS).
    pub mean2d_abs: wgpu::Buffer,
    capacity: usize,
}

impl GpuGaussianGrads {
    pub fn new(ctx: &GpuContext, capacity: usize) -> Result<Self, ModelError> {
        Ok(Self {
            parameters: GaussianParameterBuffers::new(ctx, "grads", capacity)?,
            mean2d_abs: create_per_gaussian(ctx, "grads.mean2d_abs", 2, capacity)?,
            capacity,
        })
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Records clearing every gradient buffer to zero.
    pub fn encode_zero(&self, encoder: &mut segsplat_gpu::Encoder) {
        for buffer in self.parameters.all() {
            encoder.clear_buffer(buffer, 0, None);
        }
        encoder.clear_buffer(&self.mean2d_abs, 0, None);
    }

    /// Reads `count` Gaussians' gradients back as a model-shaped struct (object ids empty).
    pub fn download(
        &self,
        ctx: &GpuContext,
        count: usize,
    ) -> Result<(GaussianModel, Vec<[f32; 2]>), ModelError> {
        let model = download_parameters(ctx, &self.parameters, count)?;
        let abs: Vec<f32> = ctx.read_vec(&self.mean2d_abs)?;
        let mean2d_abs = (0..count).map(|i| [abs[2 * i], abs[2 * i + 1]]).collect();
        Ok((model, mean2d_abs))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_names_mismatched_field() {
        let mut model = GaussianModel::default();
        model.push_simple(
            [0.0; 3],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            [0.5; 3],
            [OBJECT_NONE; 3],
        );
        model.opacity_logits.push(1.0);
        let error = model.validate().unwrap_err().to_string();
        assert!(error.contains("opacity_logits"), "{error}");
    }

    #[test]
    fn sh_rest_groups_cover_all_higher_coefficients() {
        assert_eq!(
            1 + SH_REST_GROUPS * SH_REST_COEFFICIENTS_PER_GROUP,
            SH_COEFFICIENTS
        );
    }

    #[test]
    fn two_million_gaussians_fit_lavapipe_bindings() {
        let lavapipe_limit = 128u64 << 20;
        let largest_words = (SH_REST_COEFFICIENTS_PER_GROUP * 3) as u64;
        assert!(2_000_000 * largest_words * 4 <= lavapipe_limit);
    }
}
