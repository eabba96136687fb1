//! Densification on the GPU: the decisions of [`super::plan_densification`] and the re-layout of
//! every per-Gaussian buffer (parameters, object ids, both optimiser moments) in kernels, so the
//! host reads back four counts instead of the whole model and uploads nothing.
//!
//! The pass, in three submissions:
//! 1. classify every Gaussian (grow? prune?); with a growth bound, sort the candidates by mean
//!    gradient (the radix sort), scan what each would add and refuse those past the bound;
//! 2. count each Gaussian's outputs, scan them into places, read the total back;
//! 3. write each output's origin, gather every buffer into new ones sized for the total, and
//!    move split children.
//!
//! A prune guard (Segment then Splat's object floor) decides on the CPU, between 1 and 2, from
//! the flags, object ids and opacities (20 bytes a Gaussian instead of the model's 708 down and
//! up): it needs per-object counts and an opacity order within each starving object, which the
//! floor rarely has to enforce. Its result goes back as the flags.

use bytemuck::{Pod, Zeroable};
use segsplat_gpu::kernel::{Kernel, workgroups_2d, workgroups_for};
use segsplat_gpu::scan::ExclusiveScan;
use segsplat_gpu::sort::RadixSort;
use segsplat_gpu::{GpuContext, GpuError};
use wgpu::util::DeviceExt;

use super::{DensifyConfig, DensifyThresholds, GuardInputs, PruneGuard, flag_outputs};
use crate::model::{GaussianParameterBuffers, GpuGaussians, ModelError};

const WORKGROUP: u32 = 256;
const PRUNE_BIT: u32 = 4;
const COMMON: &str = include_str!("shaders/densify_common.wgsl");

/// One densification's rules as the kernels read them (`Rules` in densify_common.wgsl).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Rules {
    count: u32,
    children: u32,
    max_new: u32,
    seed: u32,
    gradient: f32,
    log_dense_limit: f32,
    min_opacity_logit: f32,
    screen_radius: f32,
    log_world_scale: f32,
    log_shrink: f32,
    new_count: u32,
    opacity_ceiling: f32,
}

/// The gather kernel's per-buffer settings (`Gather` in densify_gather.wgsl).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct GatherRule {
    words: u32,
    fresh_zero: u32,
    new_count: u32,
    pad: u32,
}

/// The densification statistics the GPU accumulated (one entry per Gaussian each).
#[derive(Debug, Clone, Copy)]
pub struct StatBuffers<'a> {
    pub gradient_sums: &'a wgpu::Buffer,
    pub visible_counts: &'a wgpu::Buffer,
    pub max_radii: &'a wgpu::Buffer,
}

/// What densification re-lays out, as it is before.
pub struct DensifyInput<'a> {
    pub gaussians: &'a GpuGaussians,
    pub first_moments: &'a GaussianParameterBuffers,
    pub second_moments: &'a GaussianParameterBuffers,
    pub stats: StatBuffers<'a>,
}

/// The rule of one densification: [`super::plan_densification`]'s arguments.
pub struct DensifyRequest<'a> {
    pub config: &'a DensifyConfig,
    pub scene_extent: f32,
    pub guard: Option<&'a dyn PruneGuard>,
    /// At most this many new Gaussians (None: no bound).
    pub max_new: Option<usize>,
    /// The split offsets' seed (the CPU plan draws it from its generator the same way).
    pub seed: u32,
}

/// What a densification did (the same counts as a [`super::DensifyPlan`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DensifySummary {
    pub count: usize,
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
    pub spared: usize,
}

/// The re-laid-out state, in new buffers.
pub struct Densified {
    pub gaussians: GpuGaussians,
    pub first_moments: GaussianParameterBuffers,
    pub second_moments: GaussianParameterBuffers,
    pub summary: DensifySummary,
}

/// The densification kernels (see the module doc).
pub struct GpuDensifier {
    classify: Kernel,
    rank_adds: Kernel,
    admit: Kernel,
    outputs: Kernel,
    origins: Kernel,
    gather: Kernel,
    split: Kernel,
    reset: Kernel,
    scan: ExclusiveScan,
    sort: RadixSort,
}

fn kernel(ctx: &GpuContext, label: &'static str, source: &str) -> Result<Kernel, GpuError> {
    Kernel::new(ctx, label, &[COMMON, source], "main", &[])
}

/// Per-densification scratch, sized for the Gaussians before it.
struct Scratch {
    rules: wgpu::Buffer,
    flags: wgpu::Buffer,
    sort_keys: wgpu::Buffer,
    sort_values: wgpu::Buffer,
    sort_count: wgpu::Buffer,
    adds: wgpu::Buffer,
    added_before: wgpu::Buffer,
    output_counts: wgpu::Buffer,
    offsets: wgpu::Buffer,
    summary: wgpu::Buffer,
}

impl Scratch {
    fn new(ctx: &GpuContext, rules: &Rules) -> Result<Self, GpuError> {
        let words = |count: u32| u64::from(count) * 4;
        let count = rules.count;
        Ok(Self {
            rules: uniform(ctx, "densify.rules", bytemuck::bytes_of(rules)),
            flags: ctx.storage_buffer("densify.flags", words(count))?,
            sort_keys: ctx.storage_buffer("densify.sort_keys", words(count))?,
            sort_values: ctx.storage_buffer("densify.sort_values", words(count))?,
            sort_count: ctx
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("densify.sort_count"),
                    contents: bytemuck::bytes_of(&count),
                    usage: wgpu::BufferUsages::STORAGE,
                }),
            adds: ctx.storage_buffer("densify.adds", words(count))?,
            added_before: ctx.storage_buffer("densify.added_before", words(count + 1))?,
            output_counts: ctx.storage_buffer("densify.output_counts", words(count))?,
            offsets: ctx.storage_buffer("densify.offsets", words(count + 1))?,
            summary: ctx.storage_buffer("densify.summary", 16)?,
        })
    }
}

fn uniform(ctx: &GpuContext, label: &str, contents: &[u8]) -> wgpu::Buffer {
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage: wgpu::BufferUsages::UNIFORM,
        })
}

fn groups_for(ctx: &GpuContext, items: u32) -> [u32; 3] {
    workgroups_2d(
        workgroups_for(items, WORKGROUP),
        ctx.limits.max_compute_workgroups_per_dimension,
    )
}

fn encoder(ctx: &GpuContext, label: &str) -> segsplat_gpu::Encoder {
    segsplat_gpu::Encoder::new(ctx, label)
}

impl GpuDensifier {
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            classify: kernel(
                ctx,
                "densify_classify",
                include_str!("shaders/densify_classify.wgsl"),
            )?,
            rank_adds: kernel(
                ctx,
                "densify_rank_adds",
                include_str!("shaders/densify_rank_adds.wgsl"),
            )?,
            admit: kernel(
                ctx,
                "densify_admit",
                include_str!("shaders/densify_admit.wgsl"),
            )?,
            outputs: kernel(
                ctx,
                "densify_outputs",
                include_str!("shaders/densify_outputs.wgsl"),
            )?,
            origins: kernel(
                ctx,
                "densify_origins",
                include_str!("shaders/densify_origins.wgsl"),
            )?,
            gather: Kernel::new(
                ctx,
                "densify_gather",
                &[include_str!("shaders/densify_gather.wgsl")],
                "main",
                &[],
            )?,
            split: kernel(
                ctx,
                "densify_split",
                include_str!("shaders/densify_split.wgsl"),
            )?,
            reset: kernel(
                ctx,
                "densify_reset",
                include_str!("shaders/densify_reset.wgsl"),
            )?,
            scan: ExclusiveScan::new(ctx)?,
            sort: RadixSort::new(ctx)?,
        })
    }

    /// Densifies `input` by `request` into new buffers: `capacity_for(new count)` Gaussians of
    /// room when the new count exceeds the old capacity, the old capacity otherwise.
    pub fn densify(
        &mut self,
        ctx: &GpuContext,
        input: &DensifyInput<'_>,
        request: &DensifyRequest<'_>,
        capacity_for: impl Fn(usize) -> usize,
    ) -> Result<Densified, ModelError> {
        let count = u32::try_from(input.gaussians.count()).unwrap_or(u32::MAX);
        let children = request.config.split_children.max(1);
        let thresholds = DensifyThresholds::new(request.config, request.scene_extent);
        let mut rules = Rules {
            count,
            children,
            max_new: request
                .max_new
                .map_or(u32::MAX, |bound| u32::try_from(bound).unwrap_or(u32::MAX)),
            seed: request.seed,
            gradient: thresholds.gradient,
            log_dense_limit: thresholds.log_dense_limit,
            min_opacity_logit: thresholds.min_opacity_logit,
            screen_radius: thresholds.screen_radius,
            log_world_scale: thresholds.log_world_scale,
            log_shrink: (0.8 * children as f32).ln(),
            new_count: 0,
            opacity_ceiling: 0.0,
        };
        let scratch = Scratch::new(ctx, &rules)?;
        self.decide(ctx, input, &scratch, count, request.max_new.is_some())?;
        let spared = match request.guard {
            Some(guard) => spare_guarded(ctx, input, &scratch, guard, children)?,
            None => 0,
        };
        let mut summary = self.place(ctx, &scratch, count)?;
        summary.spared = spared;

        let old_capacity = input.gaussians.capacity();
        let capacity = if summary.count > old_capacity {
            capacity_for(summary.count).max(summary.count)
        } else {
            old_capacity
        };
        rules.new_count = u32::try_from(summary.count).unwrap_or(u32::MAX);
        let new_rules = uniform(ctx, "densify.rules", bytemuck::bytes_of(&rules));
        let mut densified = Densified {
            gaussians: GpuGaussians::allocate(ctx, capacity)?,
            first_moments: GaussianParameterBuffers::new(ctx, "adam.m", capacity)?,
            second_moments: GaussianParameterBuffers::new(ctx, "adam.v", capacity)?,
            summary,
        };
        self.relayout(
            ctx,
            input,
            &scratch,
            &new_rules,
            [count, rules.new_count],
            &densified,
        );
        densified.gaussians.set_count(summary.count)?;
        Ok(densified)
    }

    /// Submission 1: the flags, and the growth bound applied to them.
    fn decide(
        &mut self,
        ctx: &GpuContext,
        input: &DensifyInput<'_>,
        scratch: &Scratch,
        count: u32,
        bounded: bool,
    ) -> Result<(), GpuError> {
        let parameters = &input.gaussians.parameters;
        let stats = input.stats;
        let mut encoder = encoder(ctx, "densify decide");
        let bind = self.classify.bind(
            ctx,
            &[
                &scratch.rules,
                &parameters.log_scales,
                &parameters.opacity_logits,
                stats.gradient_sums,
                stats.visible_counts,
                stats.max_radii,
                &scratch.flags,
                &scratch.sort_keys,
                &scratch.sort_values,
            ],
        );
        self.classify
            .dispatch(&mut encoder, &bind, groups_for(ctx, count));
        if bounded && count > 0 {
            self.sort.reserve(ctx, count)?;
            self.sort.encode(
                ctx,
                &mut encoder,
                &scratch.sort_keys,
                &scratch.sort_values,
                &scratch.sort_count,
                0,
                count,
                32,
            );
            let bind = self.rank_adds.bind(
                ctx,
                &[
                    &scratch.rules,
                    &scratch.flags,
                    &scratch.sort_values,
                    &scratch.adds,
                ],
            );
            self.rank_adds
                .dispatch(&mut encoder, &bind, groups_for(ctx, count));
            self.scan.encode(
                ctx,
                &mut encoder,
                &scratch.adds,
                &scratch.added_before,
                count,
            );
            let bind = self.admit.bind(
                ctx,
                &[
                    &scratch.rules,
                    &scratch.flags,
                    &scratch.sort_values,
                    &scratch.adds,
                    &scratch.added_before,
                ],
            );
            self.admit
                .dispatch(&mut encoder, &bind, groups_for(ctx, count));
        }
        ctx.submit(encoder.finish());
        Ok(())
    }

    /// Submission 2: each Gaussian's outputs and their places; reads back the counts.
    fn place(
        &self,
        ctx: &GpuContext,
        scratch: &Scratch,
        count: u32,
    ) -> Result<DensifySummary, GpuError> {
        let mut encoder = encoder(ctx, "densify place");
        encoder.clear_buffer(&scratch.summary, 0, None);
        let bind = self.outputs.bind(
            ctx,
            &[
                &scratch.rules,
                &scratch.flags,
                &scratch.output_counts,
                &scratch.summary,
            ],
        );
        self.outputs
            .dispatch(&mut encoder, &bind, groups_for(ctx, count));
        self.scan.encode(
            ctx,
            &mut encoder,
            &scratch.output_counts,
            &scratch.offsets,
            count,
        );
        encoder.copy_buffer_to_buffer(
            &scratch.offsets,
            u64::from(count) * 4,
            &scratch.summary,
            0,
            4,
        );
        ctx.submit(encoder.finish());
        let counts: Vec<u32> = ctx.read_vec(&scratch.summary)?;
        let [total, cloned, split, pruned] = [0, 1, 2, 3].map(|i| counts[i] as usize);
        Ok(DensifySummary {
            count: total,
            cloned,
            split,
            pruned,
            spared: 0,
        })
    }

    /// Submission 3: origins, every buffer gathered into the new ones, split children moved.
    fn relayout(
        &self,
        ctx: &GpuContext,
        input: &DensifyInput<'_>,
        scratch: &Scratch,
        rules: &wgpu::Buffer,
        [count, new_count]: [u32; 2],
        out: &Densified,
    ) {
        let origin_bytes = u64::from(new_count.max(1)) * 4;
        // Origins live only for this submission; the output count was checked to fit a
        // binding when the new buffers were allocated.
        let origin_source = plain_storage(ctx, "densify.origin_source", origin_bytes);
        let origin_kind = plain_storage(ctx, "densify.origin_kind", origin_bytes);
        let mut encoder = encoder(ctx, "densify relayout");
        let bind = self.origins.bind(
            ctx,
            &[
                &scratch.rules,
                &scratch.flags,
                &scratch.offsets,
                &origin_source,
                &origin_kind,
            ],
        );
        self.origins
            .dispatch(&mut encoder, &bind, groups_for(ctx, count));

        let old = &input.gaussians.parameters;
        let new = &out.gaussians.parameters;
        let widths = parameter_widths();
        let mut copies: Vec<(&wgpu::Buffer, &wgpu::Buffer, u32, bool)> = Vec::new();
        for ((from, to), words) in old.all().into_iter().zip(new.all()).zip(widths) {
            copies.push((from, to, words, false));
        }
        copies.push((
            &input.gaussians.object_ids,
            &out.gaussians.object_ids,
            3,
            false,
        ));
        for (moments_in, moments_out) in [
            (input.first_moments, &out.first_moments),
            (input.second_moments, &out.second_moments),
        ] {
            for ((from, to), words) in moments_in
                .all()
                .into_iter()
                .zip(moments_out.all())
                .zip(widths)
            {
                copies.push((from, to, words, true));
            }
        }
        for (from, to, words, fresh_zero) in copies {
            let rule = GatherRule {
                words,
                fresh_zero: u32::from(fresh_zero),
                new_count,
                pad: 0,
            };
            let rule = uniform(ctx, "densify.gather", bytemuck::bytes_of(&rule));
            let bind = self
                .gather
                .bind(ctx, &[&rule, &origin_source, &origin_kind, from, to]);
            self.gather
                .dispatch(&mut encoder, &bind, groups_for(ctx, new_count * words));
        }
        let bind = self.split.bind(
            ctx,
            &[
                rules,
                &origin_source,
                &origin_kind,
                &old.means,
                &old.log_scales,
                &old.rotations,
                &new.means,
                &new.log_scales,
            ],
        );
        self.split
            .dispatch(&mut encoder, &bind, groups_for(ctx, new_count));
        ctx.submit(encoder.finish());
    }

    /// 3DGS's opacity reset on the GPU: opacities above `max_opacity` lowered to it, and the
    /// opacities' optimiser moments zeroed ([`super::reset_opacity_logits`] on the CPU).
    pub fn reset_opacity(
        &self,
        ctx: &GpuContext,
        gaussians: &GpuGaussians,
        first_moments: &GaussianParameterBuffers,
        second_moments: &GaussianParameterBuffers,
        max_opacity: f32,
    ) {
        let count = gaussians.count() as u32;
        let rules = Rules {
            count,
            opacity_ceiling: (max_opacity / (1.0 - max_opacity)).ln(),
            ..Zeroable::zeroed()
        };
        let rules = uniform(ctx, "densify.rules", bytemuck::bytes_of(&rules));
        let mut encoder = encoder(ctx, "opacity reset");
        let bind = self
            .reset
            .bind(ctx, &[&rules, &gaussians.parameters.opacity_logits]);
        self.reset
            .dispatch(&mut encoder, &bind, groups_for(ctx, count));
        encoder.clear_buffer(&first_moments.opacity_logits, 0, None);
        encoder.clear_buffer(&second_moments.opacity_logits, 0, None);
        ctx.submit(encoder.finish());
    }
}

/// Words a Gaussian of each parameter buffer, in [`GaussianParameterBuffers::all`]'s order.
fn parameter_widths() -> [u32; 8] {
    let rest = (crate::model::SH_REST_COEFFICIENTS_PER_GROUP * 3) as u32;
    [3, 3, 4, 1, 3, rest, rest, rest]
}

fn plain_storage(ctx: &GpuContext, label: &str, bytes: u64) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16),
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    })
}

/// The prune guard's veto, on the CPU from the flags, object ids and opacities; the spared
/// candidates' prune bits are cleared in the flags on the GPU. Returns how many were spared.
fn spare_guarded(
    ctx: &GpuContext,
    input: &DensifyInput<'_>,
    scratch: &Scratch,
    guard: &dyn PruneGuard,
    children: u32,
) -> Result<usize, GpuError> {
    let count = input.gaussians.count();
    let mut flags: Vec<u32> = ctx.read_vec(&scratch.flags)?;
    flags.truncate(count);
    let mut prune: Vec<bool> = flags.iter().map(|f| f & PRUNE_BIT != 0).collect();
    let candidates = prune.iter().filter(|&&p| p).count();
    if candidates == 0 {
        return Ok(0);
    }
    let ids: Vec<u32> = ctx.read_vec(&input.gaussians.object_ids)?;
    let object_ids: Vec<[u32; 3]> = ids
        .chunks_exact(3)
        .take(count)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let mut opacity_logits: Vec<f32> = ctx.read_vec(&input.gaussians.parameters.opacity_logits)?;
    opacity_logits.truncate(count);
    let survivors: Vec<u32> = flags.iter().map(|&f| flag_outputs(f, children)).collect();
    guard.spare(
        GuardInputs {
            object_ids: &object_ids,
            opacity_logits: &opacity_logits,
        },
        &mut prune,
        &survivors,
    );
    let mut spared = 0;
    for (flag, pruned) in flags.iter_mut().zip(&prune) {
        if *flag & PRUNE_BIT != 0 && !pruned {
            *flag &= !PRUNE_BIT;
            spared += 1;
        }
    }
    if spared > 0 {
        ctx.queue
            .write_buffer(&scratch.flags, 0, bytemuck::cast_slice(&flags));
    }
    Ok(spared)
}
