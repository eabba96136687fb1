// Per-splat gradient emission for the column backward with subgroups: the subgroup sums its
// invocations' gradients by a butterfly of shuffles, and one invocation adds the sums, so a CPU
// adapter runs one compare-and-swap loop per slot instead of one per lane (lavapipe, 512 px, 200k
// random Gaussians: column backward 1041 ms with atomics per invocation, 933 ms with
// subgroupAdd, 812 ms with shuffles; a reduce-scatter that needs 15 shuffles instead of 33 was
// no faster). naga takes the subgroup builtins from the device's SUBGROUP feature.

var<private> subgroup_lane: u32;
var<private> subgroup_lanes: u32;

// Called once, in uniform control flow, before any emission.
fn emit_setup() {
    subgroup_lane = subgroupExclusiveAdd(1u);
    subgroup_lanes = subgroupAdd(1u);
}

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

// Must be called in uniform control flow by every invocation; `grads` are zero where nothing
// contributes.
fn emit_fragment_grads(gaussian: u32, grads: FragmentGrads, contributes: bool) {
    if !subgroupAny(contributes) {
        return;
    }
    var total = grads;
    for (var mask = 1u; mask < subgroup_lanes; mask <<= 1u) {
        total = sum_fragment_grads(total, shuffled(total, mask));
    }
    if subgroup_lane == 0u {
        add_fragment_grads(gaussian, total);
    }
}
