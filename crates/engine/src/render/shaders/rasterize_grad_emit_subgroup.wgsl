// Per-fragment gradient emission with subgroups: every invocation of a subgroup works on the same
// Gaussian at the same time (the batch loop is uniform), so the subgroup sums its fragments'
// gradients first and one invocation adds the sums: subgroup-size times fewer atomics on the
// hottest addresses (8 on lavapipe's 256-bit lanes, 32 on NVIDIA). naga takes the subgroup
// builtins from the device's SUBGROUP feature (it rejects `enable subgroups;`).

// Must be called in uniform control flow by every invocation; the caller passes zero gradients
// for fragments that do not contribute.
fn emit_fragment_grads(gaussian: u32, grads: FragmentGrads, contributes: bool) {
    if !subgroupAny(contributes) {
        return;
    }
    let mean = subgroupAdd(grads.mean);
    let conic = subgroupAdd(grads.conic);
    let colour = subgroupAdd(grads.colour);
    let opacity = subgroupAdd(grads.opacity);
    let mean_abs = subgroupAdd(grads.mean_abs);
    // naga has no subgroupElect: the invocation with no active one before it adds.
    if subgroupExclusiveAdd(1u) == 0u {
        add_fragment_grads(gaussian, FragmentGrads(mean, conic, colour, opacity, mean_abs));
    }
}
