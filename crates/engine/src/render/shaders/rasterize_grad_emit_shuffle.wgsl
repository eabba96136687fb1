// Gradient emission for the column backward (rasterize_backward_columns.wgsl): the subgroup sums
// its invocations' gradients of one splat by a butterfly of xor shuffles (one vector permute each
// on lavapipe), after which every lane holds the sums and lane k adds slot k, so the 11 atomics
// run side by side in one or two passes over the lanes instead of one pass each. lavapipe, 512 px,
// 200k random Gaussians, column backward in ms: atomics from every invocation 1041, subgroupAdd
// 933, butterfly with one lane adding 812; with lane chunks (rasterize_lane_chunk.wgsl), 493 with
// one lane adding and 430 with a slot per lane. A reduce-scatter (15 shuffles instead of 33) was
// no faster. naga takes the subgroup builtins from the device's SUBGROUP feature.

// The partner invocation's gradients (lane index xor `mask`).
fn shuffled(grads: FragmentGrads, mask: u32) -> FragmentGrads {
    return FragmentGrads(
        subgroupShuffleXor(grads.mean, mask),
        subgroupShuffleXor(grads.conic, mask),
        subgroupShuffleXor(grads.colour, mask),
        subgroupShuffleXor(grads.opacity, mask),
        subgroupShuffleXor(grads.mean_abs, mask),
    );
}

// Slot `slot` of grad_projected's layout (rasterize_grad_fragment.wgsl).
fn grad_slot(grads: FragmentGrads, slot: u32) -> f32 {
    var value = grads.mean.x;
    value = select(value, grads.mean.y, slot == 1u);
    value = select(value, grads.conic.x, slot == 2u);
    value = select(value, grads.conic.y, slot == 3u);
    value = select(value, grads.conic.z, slot == 4u);
    value = select(value, grads.colour.x, slot == 5u);
    value = select(value, grads.colour.y, slot == 6u);
    value = select(value, grads.colour.z, slot == 7u);
    value = select(value, grads.opacity, slot == 8u);
    value = select(value, grads.mean_abs.x, slot == 9u);
    return select(value, grads.mean_abs.y, slot == 10u);
}

// Must be called in uniform control flow by every invocation; `grads` are zero where nothing
// contributes.
fn emit_lane_sums(gaussian: u32, grads: FragmentGrads, contributes: bool, lane: u32, lanes: u32) {
    if !subgroupAny(contributes) {
        return;
    }
    var total = grads;
    for (var mask = 1u; mask < lanes; mask <<= 1u) {
        total = sum_fragment_grads(total, shuffled(total, mask));
    }
    let slots = emitted_grad_slots();
    for (var slot = lane; slot < slots; slot += lanes) {
        add_grad(gaussian, slot, grad_slot(total, slot));
    }
}
