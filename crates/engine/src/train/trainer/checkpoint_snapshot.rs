//! Checkpoints without a blocking read-back (issue 38, item 4). The step loop records GPU copies
//! of everything [`Trainer::checkpoint`] reads and submits them with the host-side state of
//! that moment ([`TrainerMeta`]); whoever finishes the [`PendingCheckpoint`] (the job's
//! checkpoint writer thread) waits for those copies alone and builds the same checkpoint, bit
//! for bit, while the loop trains on.

use segsplat_gpu::snapshot_copies::{CopyStaging, PendingCopies};

use super::checkpointing::checkpoint_from_state;
use super::{TrainError, Trainer, TrainerMeta};
use crate::OBJECT_NONE;
use crate::checkpoint::Checkpoint;
use crate::densify::DensifyStats;
use crate::model::{GaussianModel, PARAMETER_WORDS, parameters_from_words};

/// Buffers a snapshot copies, in this order: the Gaussians' parameters, their object ids, the
/// two Adam moments, the three densification statistics, then (dynamic scenes) the
/// deformation field's parameters and moments.
const PARAMETERS: usize = PARAMETER_WORDS.len();
const OBJECT_IDS: usize = PARAMETERS;
const FIRST_MOMENTS: usize = OBJECT_IDS + 1;
const SECOND_MOMENTS: usize = FIRST_MOMENTS + PARAMETERS;
const STATISTICS: usize = SECOND_MOMENTS + PARAMETERS;
const FIELD: usize = STATISTICS + 3;

/// A checkpoint whose arrays are on their way from the GPU: the state of the step it was
/// taken at, whatever the trainer has done since.
#[derive(Debug)]
pub struct PendingCheckpoint {
    meta: TrainerMeta,
    copies: PendingCopies,
    /// Words of the deformation field's parameters (dynamic scenes).
    field_parameters: Option<usize>,
}

impl Trainer {
    /// Records and submits copies of the trainer's state into `staging` (grown where too
    /// small) and returns at once: no wait for the device, no read-back on this thread.
    /// [`PendingCheckpoint::finish`] gives what [`Self::checkpoint`] would have given here.
    pub fn checkpoint_snapshot(
        &self,
        staging: CopyStaging,
    ) -> Result<PendingCheckpoint, TrainError> {
        let count = self.gaussians.count();
        let mut sources: Vec<(&wgpu::Buffer, u64)> = Vec::new();
        sources.extend(self.gaussians.parameters.extents(count));
        sources.push((&self.gaussians.object_ids, (count * 3 * 4) as u64));
        sources.extend(self.first_moments.extents(count));
        sources.extend(self.second_moments.extents(count));
        let stats = self.accumulators.buffers();
        for buffer in [stats.gradient_sums, stats.visible_counts, stats.max_radii] {
            sources.push((buffer, (count * 4) as u64));
        }
        let field_parameters = self.dynamics.as_ref().map(|dynamics| {
            let field = &dynamics.field;
            let bytes = (field.parameter_count() * 4) as u64;
            for buffer in [&field.parameters, &field.first_moment, &field.second_moment] {
                sources.push((buffer, bytes));
            }
            field.parameter_count()
        });
        let copies = staging.copy(&self.ctx, &sources)?;
        Ok(PendingCheckpoint {
            meta: self.checkpoint_meta(),
            copies,
            field_parameters,
        })
    }
}

impl PendingCheckpoint {
    /// The step the snapshot was taken at.
    pub fn step(&self) -> u32 {
        self.meta.step
    }

    /// Bytes the snapshot copies from the GPU.
    pub fn bytes(&self) -> u64 {
        self.copies.bytes()
    }

    /// Waits for the snapshot's copies (not for the steps submitted after them) and builds the
    /// checkpoint; hands back the staging buffers for the next snapshot.
    pub fn finish(self) -> Result<(Checkpoint<TrainerMeta>, CopyStaging), TrainError> {
        let Self {
            meta,
            copies,
            field_parameters,
        } = self;
        let (bytes, staging) = copies.read()?;
        let count = meta.gaussians;
        let parameters = |first: usize| {
            let words: [Vec<f32>; PARAMETERS] = std::array::from_fn(|index| {
                values(&bytes[first + index], count * PARAMETER_WORDS[index])
            });
            parameters_from_words(&words, count)
        };
        let mut model = parameters(0);
        let ids: Vec<u32> = values(&bytes[OBJECT_IDS], count * 3);
        model.object_ids = ids
            .chunks_exact(3)
            .map(|id| [id[0], id[1], id[2]])
            .collect();
        let moments = |first: usize| GaussianModel {
            object_ids: vec![[OBJECT_NONE; 3]; count],
            ..parameters(first)
        };
        let first = moments(FIRST_MOMENTS);
        let second = moments(SECOND_MOMENTS);
        let stats = DensifyStats {
            gradient_sums: values(&bytes[STATISTICS], count),
            visible_counts: values(&bytes[STATISTICS + 1], count),
            max_radii: values(&bytes[STATISTICS + 2], count),
        };
        let field = field_parameters
            .map(|words| std::array::from_fn(|index| values(&bytes[FIELD + index], words)));
        let checkpoint = checkpoint_from_state(meta, &model, &first, &second, &stats, field);
        Ok((checkpoint, staging))
    }
}

/// The first `len` values of a copy (a copy of nothing still holds one word).
fn values<T: bytemuck::Pod>(bytes: &[u8], len: usize) -> Vec<T> {
    let mut values: Vec<T> = bytemuck::pod_collect_to_vec(bytes);
    values.truncate(len);
    values
}
