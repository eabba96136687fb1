// Per-fragment gradient emission without subgroup sums: each pixel adds its own fragment's
// gradients into grad_projected (one atomic per non-zero slot).

// Called by every invocation of the workgroup for the same `gaussian`; `contributes` is false
// where the fragment does not contribute.
fn emit_fragment_grads(gaussian: u32, grads: FragmentGrads, contributes: bool) {
    if contributes {
        add_fragment_grads(gaussian, grads);
    }
}
