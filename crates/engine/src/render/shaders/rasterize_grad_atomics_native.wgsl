// Float accumulation into `grad_projected` with native f32 atomics (SHADER_FLOAT32_ATOMIC).
// (naga rejects storage pointers as function arguments, so the helper names the array.)
alias AtomicF32 = atomic<f32>;
fn grad_projected_add(index: u32, value: f32) {
    atomicAdd(&grad_projected[index], value);
}
