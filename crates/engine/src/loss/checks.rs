//! A loss's inputs checked before anything is recorded: slot tables, buffer sizes and content
//! hints, so a wrong size is an error naming the buffer rather than zeros read past its end.

use super::{
    LossError, LossImages, LossOutputs, MAX_ID_MAPS, ObjectContentHints, ObjectLossImages,
    SKIP_CELL,
};

/// A batch's slots, checked, in the kernels' table layout.
pub(super) fn slot_table(images: &ObjectLossImages<'_>) -> Result<Vec<[u32; 4]>, LossError> {
    if images.id_maps.len() > MAX_ID_MAPS {
        return Err(LossError::TooManyIdMaps(images.id_maps.len()));
    }
    images
        .slots
        .iter()
        .enumerate()
        .map(|(slot, object)| {
            if object.id_map as usize >= images.id_maps.len() {
                return Err(LossError::UnknownIdMap {
                    slot,
                    id_map: object.id_map,
                    maps: images.id_maps.len(),
                });
            }
            Ok([object.id_map, object.object_id, 0, 0])
        })
        .collect()
}

/// Rejects buffers too small for `slots` losses of the image, which the kernels would otherwise
/// read as zeros.
pub(super) fn check_sizes(
    images: &LossImages<'_>,
    id_maps: &[&wgpu::Buffer],
    slots: u32,
    outputs: &LossOutputs<'_>,
) -> Result<(), LossError> {
    let (width, height) = (images.width, images.height);
    let pixels = u64::from(width) * u64::from(height);
    if pixels == 0 {
        return Err(LossError::EmptyImage { width, height });
    }
    let slots = u64::from(slots);
    let mut required = vec![
        (
            "rendered image",
            images.rendered,
            (u64::from(images.rendered_index) + slots) * pixels * 16,
        ),
        ("target image", images.target, pixels * 16),
        (
            "rendered gradient",
            outputs.rendered_grad,
            (u64::from(outputs.grad_index) + slots) * pixels * 16,
        ),
        (
            "loss values",
            outputs.loss_values,
            (u64::from(outputs.loss_slot) + slots) * 4,
        ),
    ];
    required.extend(
        id_maps
            .iter()
            .map(|map| ("target object ids", *map, pixels * 4)),
    );
    require_sizes(required, width, height)
}

/// Fails on the first buffer smaller than the bytes a `width x height` loss needs of it.
pub(super) fn require_sizes<'b>(
    required: impl IntoIterator<Item = (&'static str, &'b wgpu::Buffer, u64)>,
    width: u32,
    height: u32,
) -> Result<(), LossError> {
    for (what, buffer, needed_bytes) in required {
        if buffer.size() < needed_bytes {
            return Err(LossError::BufferTooSmall {
                what,
                actual_bytes: buffer.size(),
                needed_bytes,
                width,
                height,
            });
        }
    }
    Ok(())
}

/// Squares of [`SKIP_CELL`] pixels in a `width x height` image.
pub(super) fn cell_count(width: u32, height: u32) -> u64 {
    u64::from(width.div_ceil(SKIP_CELL)) * u64::from(height.div_ceil(SKIP_CELL))
}

/// Checks a batch's content hints against its images: a cell map per id map, each large enough.
pub(super) fn check_content_hints(
    images: &ObjectLossImages<'_>,
    content: &ObjectContentHints<'_>,
) -> Result<(), LossError> {
    if content.cell_maps.len() != images.id_maps.len() {
        return Err(LossError::CellMapCount {
            cell_maps: content.cell_maps.len(),
            id_maps: images.id_maps.len(),
        });
    }
    let (width, height) = (images.width, images.height);
    let cell_bytes = cell_count(width, height) * 4;
    let images_needed = u64::from(images.rendered_index) + images.slots.len() as u64;
    let required = std::iter::once((
        "render occupancy",
        content.occupancy,
        images_needed * cell_bytes,
    ))
    .chain(
        content
            .cell_maps
            .iter()
            .map(|map| ("cell map", *map, cell_bytes)),
    );
    require_sizes(required, width, height)
}
