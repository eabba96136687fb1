// Float accumulation into `grad_projected` by compare-and-swap on the f32 bit pattern, for
// adapters without native f32 atomics.
alias AtomicF32 = atomic<u32>;
fn grad_projected_add(index: u32, value: f32) {
    var old = atomicLoad(&grad_projected[index]);
    loop {
        let new_bits = bitcast<u32>(bitcast<f32>(old) + value);
        let result = atomicCompareExchangeWeak(&grad_projected[index], old, new_bits);
        if result.exchanged {
            break;
        }
        old = result.old_value;
    }
}
