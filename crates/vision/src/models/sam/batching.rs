//! Which prompts may share one decoder run, read off the decoder's declared input shapes.
//!
//! Decoders come in three batch shapes, all in use:
//! - segsplat's own export: every prompt input has a dynamic batch dimension, so a run carries a
//!   chunk of prompts, each with its own mask prior;
//! - segment-anything's own export (`SamOnnxModel`, copied by MobileSAM): `point_coords [1, N, 2]`,
//!   one prompt per run;
//! - common SAM 2 exports: `point_coords [B, N, 2]` but `mask_input [1, 1, 256, 256]` and
//!   `has_mask_input [1]`, broadcast over the batch, so prompts batch only while they agree on
//!   the mask prior: all without one share a run, a prompt with a prior runs alone.

use crate::models::manifest::ModelEntry;

use super::predictor::SamPrompt;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecoderBatching {
    /// `point_coords` has batch dimension 1: one prompt per run.
    pub one_prompt_per_run: bool,
    /// `mask_input` / `has_mask_input` have batch dimension 1 and are broadcast over the prompts.
    pub shared_mask_input: bool,
}

impl DecoderBatching {
    pub fn of(decoder: &ModelEntry) -> DecoderBatching {
        let batch_is_one = |name: &str| {
            decoder
                .inputs
                .iter()
                .find(|spec| spec.name == name)
                .and_then(|spec| spec.shape.first())
                .is_some_and(|dim| *dim == 1)
        };
        DecoderBatching {
            one_prompt_per_run: batch_is_one("point_coords") || batch_is_one("point_labels"),
            shared_mask_input: batch_is_one("mask_input") || batch_is_one("has_mask_input"),
        }
    }

    /// Whether the decoder can answer several prompts at all in one run.
    pub fn batches(&self) -> bool {
        !self.one_prompt_per_run
    }

    /// One line for reports: how this decoder's runs are shaped.
    pub fn describe(&self) -> &'static str {
        match (self.one_prompt_per_run, self.shared_mask_input) {
            (true, _) => "one prompt per run (the graph fixes point_coords' batch at 1)",
            (false, true) => {
                "prompts without a mask prior batched; a prompt with one runs alone (mask_input broadcast)"
            }
            (false, false) => "prompts batched, each with its own mask prior",
        }
    }

    /// Splits `prompts` into consecutive runs of at most `chunk` prompts that one decoder run can
    /// carry: the same number of point tokens (`token_counts`), and the mask-prior rule above.
    /// Returns `(start, end)` ranges covering `prompts` in order.
    pub fn runs(
        &self,
        prompts: &[SamPrompt],
        token_counts: &[usize],
        chunk: usize,
    ) -> Vec<(usize, usize)> {
        let chunk = if self.one_prompt_per_run {
            1
        } else {
            chunk.max(1)
        };
        let alone = |prompt: &SamPrompt| self.shared_mask_input && prompt.mask_input.is_some();
        let mut runs = Vec::new();
        let mut start = 0;
        while start < prompts.len() {
            let mut end = start + 1;
            if !alone(&prompts[start]) {
                while end < prompts.len()
                    && end - start < chunk
                    && token_counts[end] == token_counts[start]
                    && !alone(&prompts[end])
                {
                    end += 1;
                }
            }
            runs.push((start, end));
            start = end;
        }
        runs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prompt(with_mask: bool) -> SamPrompt {
        SamPrompt {
            points: vec![([1.0, 1.0], super::super::predictor::PointLabel::Foreground)],
            bounding_box: None,
            mask_input: with_mask.then(|| vec![0.0; 4]),
        }
    }

    #[test]
    fn batched_decoders_group_by_token_count_and_chunk() {
        let batching = DecoderBatching {
            one_prompt_per_run: false,
            shared_mask_input: false,
        };
        let prompts: Vec<SamPrompt> = (0..6).map(|i| prompt(i == 2)).collect();
        assert_eq!(
            batching.runs(&prompts, &[2, 2, 2, 3, 3, 3], 2),
            vec![(0, 2), (2, 3), (3, 5), (5, 6)]
        );
    }

    #[test]
    fn broadcast_mask_input_runs_prompts_with_a_prior_alone() {
        let batching = DecoderBatching {
            one_prompt_per_run: false,
            shared_mask_input: true,
        };
        let prompts: Vec<SamPrompt> = [false, false, true, false, true, true, false]
            .into_iter()
            .map(prompt)
            .collect();
        assert_eq!(
            batching.runs(&prompts, &[2; 7], 16),
            vec![(0, 2), (2, 3), (3, 4), (4, 5), (5, 6), (6, 7)]
        );
    }

    #[test]
    fn fixed_batch_decoders_take_one_prompt_per_run() {
        let batching = DecoderBatching {
            one_prompt_per_run: true,
            shared_mask_input: true,
        };
        let prompts: Vec<SamPrompt> = (0..3).map(|_| prompt(false)).collect();
        assert_eq!(
            batching.runs(&prompts, &[2; 3], 16),
            vec![(0, 1), (1, 2), (2, 3)]
        );
    }
}
