//! `ExclusiveScan` against a CPU prefix sum (exact: integer sums, wrapping like the GPU), the
//! deferred read-back the training loop reads its progress with (`DeferredRead`), the
//! context's kernel cache every kernel is built through, the encoder whose dispatches share
//! a compute pass, and what several threads recording on one context share: the uniform ring
//! kernels' parameters go through and the kernel profiler.

mod gpu_support;

use gpu_support::{gpu_context, new_encoder, new_gpu_context, seeded_rng, storage_buffer, submit};
use rand::Rng;
use segsplat_gpu::{ExclusiveScan, Kernel, WorkgroupSum};

fn cpu_exclusive_scan(input: &[u32]) -> Vec<u32> {
    let mut output = Vec::with_capacity(input.len() + 1);
    let mut total = 0u32;
    output.push(0);
    for &value in input {
        total = total.wrapping_add(value);
        output.push(total);
    }
    output
}

/// Scans `input` into a buffer with room for `count + 1 + 5` values, the extra five holding a
/// sentinel that the scan must leave alone.
fn check_scan(scan: &ExclusiveScan, input: &[u32]) {
    let Some(ctx) = gpu_context() else { return };
    const SENTINEL: u32 = 0xdead_beef;
    let input_buffer = storage_buffer(ctx, "scan input", input);
    let output_buffer = storage_buffer(ctx, "scan output", &vec![SENTINEL; input.len() + 6]);
    let mut encoder = new_encoder(ctx);
    scan.encode(
        ctx,
        &mut encoder,
        &input_buffer,
        &output_buffer,
        input.len() as u32,
    );
    submit(ctx, encoder);
    let output: Vec<u32> = ctx.read_vec(&output_buffer).unwrap();
    let expected = cpu_exclusive_scan(input);
    let first_mismatch = (0..expected.len()).find(|&i| output[i] != expected[i]);
    assert_eq!(
        first_mismatch,
        None,
        "count {}: first mismatch at {:?}",
        input.len(),
        first_mismatch.map(|i| (i, output[i], expected[i]))
    );
    assert!(
        output[expected.len()..expected.len() + 5]
            .iter()
            .all(|&v| v == SENTINEL),
        "count {}: scan wrote beyond count + 1",
        input.len()
    );
}

#[test]
fn scan_matches_cpu_for_block_boundary_and_large_counts() {
    let Some(ctx) = gpu_context() else { return };
    // Every way of summing over a workgroup the adapter has, whichever it picks.
    for sum in WorkgroupSum::supported(ctx) {
        let scan = ExclusiveScan::with_sum(ctx, sum).unwrap();
        let mut rng = seeded_rng(7);
        for count in [
            0usize, 1, 255, 256, 257, 1023, 1024, 1025, 100_000, 1_000_000,
        ] {
            let input: Vec<u32> = (0..count).map(|_| rng.random_range(0..1000)).collect();
            check_scan(&scan, &input);
        }
    }
}

#[test]
fn scan_wraps_full_range_values_like_cpu() {
    let Some(ctx) = gpu_context() else { return };
    let scan = ExclusiveScan::new(ctx).unwrap();
    let mut rng = seeded_rng(11);
    let input: Vec<u32> = (0..70_001).map(|_| rng.random()).collect();
    check_scan(&scan, &input);
}

#[test]
fn three_level_scan_matches_cpu() {
    let Some(ctx) = gpu_context() else { return };
    let scan = ExclusiveScan::new(ctx).unwrap();
    // More than 1024 * 1024 + 1 outputs needs a third level.
    let input: Vec<u32> = (0..1_100_000u32).map(|i| i % 7).collect();
    check_scan(&scan, &input);
}

#[test]
fn scans_sharing_one_encoder_use_their_own_counts() {
    let Some(ctx) = gpu_context() else { return };
    let scan = ExclusiveScan::new(ctx).unwrap();
    let large: Vec<u32> = (0..300_000u32).map(|i| i % 5).collect();
    let small: Vec<u32> = (0..3_000u32).map(|i| i % 3 + 1).collect();
    let large_in = storage_buffer(ctx, "large", &large);
    let small_in = storage_buffer(ctx, "small", &small);
    let large_out = storage_buffer(ctx, "large out", &vec![0u32; large.len() + 1]);
    let small_out = storage_buffer(ctx, "small out", &vec![0u32; small.len() + 1]);
    let mut encoder = new_encoder(ctx);
    scan.encode(ctx, &mut encoder, &large_in, &large_out, large.len() as u32);
    scan.encode(ctx, &mut encoder, &small_in, &small_out, small.len() as u32);
    submit(ctx, encoder);
    assert_eq!(
        ctx.read_vec::<u32>(&large_out).unwrap(),
        cpu_exclusive_scan(&large)
    );
    assert_eq!(
        ctx.read_vec::<u32>(&small_out).unwrap(),
        cpu_exclusive_scan(&small)
    );
}

/// A deferred read hands back the newest copy requested (never an older one once a newer has
/// arrived), skips a request while two copies are on their way, and `read_now` waits for the
/// newest; each delivery is one counted read-back.
#[test]
fn deferred_reads_deliver_the_newest_copy() {
    use segsplat_gpu::deferred_read::DeferredRead;
    if gpu_context().is_none() {
        return;
    }
    // A context of its own: the read-backs counted must be this test's alone.
    let ctx = &segsplat_gpu::GpuContext::new_default().expect("GPU context");
    let source = storage_buffer(ctx, "deferred source", &[0u32; 4]);
    let mut read = DeferredRead::new(ctx, "deferred test", 16);
    let request = |read: &mut DeferredRead, values: [u32; 4]| {
        ctx.queue
            .write_buffer(&source, 0, bytemuck::cast_slice(&values));
        let mut encoder = new_encoder(ctx);
        let slot = read.record(&mut encoder, &source);
        submit(ctx, encoder);
        if let Some(slot) = slot {
            read.after_submit(slot);
        }
        slot.is_some()
    };
    let as_u32 = |bytes: Vec<u8>| bytemuck::pod_collect_to_vec::<u8, u32>(&bytes);

    assert_eq!(read.read_now(ctx).unwrap(), None, "nothing was asked");
    assert!(request(&mut read, [1, 2, 3, 4]));
    assert_eq!(
        read.read_now(ctx).unwrap().map(as_u32),
        Some(vec![1, 2, 3, 4])
    );
    assert_eq!(read.take(ctx).unwrap(), None, "a copy is delivered once");

    // Two requests before a take: the newer wins.
    assert!(request(&mut read, [5, 6, 7, 8]));
    assert!(request(&mut read, [9, 10, 11, 12]));
    ctx.wait_idle().unwrap();
    assert_eq!(
        read.take(ctx).unwrap().map(as_u32),
        Some(vec![9, 10, 11, 12])
    );

    // Finished copies nobody took are recycled for newer requests.
    let before = ctx.host_costs.reading();
    for round in 0..5u32 {
        assert!(request(&mut read, [round; 4]));
        ctx.wait_idle().unwrap();
    }
    assert_eq!(read.take(ctx).unwrap().map(as_u32), Some(vec![4; 4]));
    let counted = ctx.host_costs.reading().since(&before);
    assert_eq!((counted.read_backs, counted.bytes_read_back), (1, 16));
}

/// A kernel compiles once per context (`segsplat_gpu::kernel_cache`): asking again reuses the
/// pipeline, which still runs; a source the device rejects is an error every time and is never
/// kept. On a context of its own, so the counts are this test's alone.
#[test]
fn kernels_compile_once_per_context_and_rejected_ones_are_not_kept() {
    if gpu_context().is_none() {
        return;
    }
    let ctx = segsplat_gpu::GpuContext::new_default().expect("a second context on the adapter");
    let source = "@group(0) @binding(0) var<storage, read_write> data: array<u32>;\n\
                  @compute @workgroup_size(1) fn main() { data[0] = data[0] + 7u; }";
    let first = Kernel::new(&ctx, "cache_probe", &[source], "main", &[]).unwrap();
    let compiles = ctx.kernel_compiles();
    assert_eq!((compiles.compiled, compiles.reused), (1, 0));
    assert!(compiles.compile_seconds > 0.0);
    let second = Kernel::new(&ctx, "cache_probe", &[source], "main", &[]).unwrap();
    let compiles = ctx.kernel_compiles();
    assert_eq!((compiles.compiled, compiles.reused), (1, 1));

    let data = storage_buffer(&ctx, "cache probe data", &[1u32]);
    let mut encoder = new_encoder(&ctx);
    for kernel in [&first, &second] {
        let bound = kernel.bind(&ctx, &[&data]);
        kernel.dispatch(&mut encoder, &bound, [1, 1, 1]);
    }
    submit(&ctx, encoder);
    assert_eq!(ctx.read_vec::<u32>(&data).unwrap(), vec![15]);

    let broken = "@compute @workgroup_size(1) fn main() { let x: u32 = 1.5; }";
    for _ in 0..2 {
        let error = Kernel::new(&ctx, "cache_probe_broken", &[broken], "main", &[]).unwrap_err();
        assert!(
            error.to_string().contains("cache_probe_broken"),
            "the error names the kernel: {error}"
        );
    }
    let compiles = ctx.kernel_compiles();
    assert_eq!((compiles.compiled, compiles.reused), (1, 1));
}

/// Consecutive dispatches share one compute pass (`segsplat_gpu::Encoder`), and wgpu still
/// orders them: the second reads what the first wrote across the whole buffer. A copy recorded
/// between dispatches ends the pass, so it sees the dispatches before it and the dispatch after
/// it sees the copy. On a context of its own, so the pass count is this test's alone.
#[test]
fn dispatches_share_a_pass_in_order_until_something_else_is_recorded() {
    if gpu_context().is_none() {
        return;
    }
    let ctx = segsplat_gpu::GpuContext::new_default().expect("a second context on the adapter");
    let source = "@group(0) @binding(0) var<storage, read_write> input: array<u32>;\n\
                  @group(0) @binding(1) var<storage, read_write> output: array<u32>;\n\
                  @compute @workgroup_size(64) fn main(@builtin(global_invocation_id) id: vec3<u32>) {\n\
                      output[id.x] = input[id.x] * 3u + 1u;\n\
                  }";
    let kernel = Kernel::new(&ctx, "pass_probe", &[source], "main", &[]).unwrap();
    // Large enough that a missing barrier would let a later dispatch's workgroups overtake
    // the earlier one's on a GPU.
    const COUNT: usize = 1 << 16;
    let start: Vec<u32> = (0..COUNT as u32).collect();
    let [a, b, c, d] = ["a", "b", "c", "d"].map(|label| storage_buffer(&ctx, label, &start));
    let groups = [(COUNT / 64) as u32, 1, 1];
    let step = |x: u32| x.wrapping_mul(3).wrapping_add(1);

    let before = ctx.host_costs.reading();
    let mut encoder = new_encoder(&ctx);
    kernel.dispatch(&mut encoder, &kernel.bind(&ctx, &[&a, &b]), groups);
    kernel.dispatch(&mut encoder, &kernel.bind(&ctx, &[&b, &c]), groups);
    encoder.copy_buffer_to_buffer(&c, 0, &d, 0, (COUNT * 4) as u64);
    kernel.dispatch(&mut encoder, &kernel.bind(&ctx, &[&d, &a]), groups);
    submit(&ctx, encoder);
    let passes = ctx.host_costs.reading().since(&before).compute_passes;
    assert_eq!(
        passes, 2,
        "two dispatches in one pass, the third after the copy in another"
    );

    let expected_c: Vec<u32> = start.iter().map(|&x| step(step(x))).collect();
    let expected_a: Vec<u32> = expected_c.iter().map(|&x| step(x)).collect();
    assert_eq!(ctx.read_vec::<u32>(&c).unwrap(), expected_c);
    assert_eq!(ctx.read_vec::<u32>(&d).unwrap(), expected_c);
    assert_eq!(ctx.read_vec::<u32>(&a).unwrap(), expected_a);

    // `end_pass` gives each dispatch a pass of its own, as every dispatch had before.
    let before = ctx.host_costs.reading();
    let mut encoder = new_encoder(&ctx);
    for _ in 0..3 {
        kernel.dispatch(&mut encoder, &kernel.bind(&ctx, &[&a, &b]), groups);
        encoder.end_pass();
    }
    submit(&ctx, encoder);
    assert_eq!(ctx.host_costs.reading().since(&before).compute_passes, 3);
}

/// A small ring, so that a few hundred pushes go round it many times.
const SMALL_RING: u64 = 4096;

/// Records a copy of `value` through the uniform ring into `target` (what a kernel's parameters
/// go through), without submitting it.
fn record_upload(
    ctx: &segsplat_gpu::GpuContext,
    value: u32,
    target: &wgpu::Buffer,
) -> segsplat_gpu::Encoder {
    let mut encoder = new_encoder(ctx);
    ctx.encode_upload(&mut encoder, bytemuck::bytes_of(&[value; 4]), target, 0);
    encoder
}

/// A thread still recording keeps its parameters while another thread pushes and submits round
/// the ring many times. Before stop 58 any submission freed the whole ring, so the other
/// thread's later pushes overwrote the recording's slot and it read their values: the NVIDIA
/// H200's wrong deformation-field products in `deform_gpu`'s parallel tests.
#[test]
fn a_recording_keeps_its_kernel_parameters_while_other_threads_submit() {
    let Some(ctx) = new_gpu_context() else { return };
    let ctx = ctx.with_uniform_ring_bytes(SMALL_RING);
    let mine = storage_buffer(&ctx, "recording's target", &[0u32; 4]);
    let recording = record_upload(&ctx, 7, &mine);
    std::thread::scope(|scope| {
        scope.spawn(|| {
            let theirs = storage_buffer(&ctx, "other thread's target", &[0u32; 4]);
            for value in 1000..1000 + 4 * SMALL_RING as u32 / 16 {
                submit(&ctx, record_upload(&ctx, value, &theirs));
            }
            let last: Vec<u32> = ctx.read_vec(&theirs).expect("read");
            assert_eq!(last, [999 + 4 * SMALL_RING as u32 / 16; 4]);
        });
    });
    assert_eq!(
        ctx.uniform_ring_open_threads(),
        1,
        "the recording thread's slot is protected"
    );
    submit(&ctx, recording);
    assert_eq!(ctx.uniform_ring_open_threads(), 0);
    let read: Vec<u32> = ctx.read_vec(&mine).expect("read");
    assert_eq!(
        read, [7; 4],
        "the recording read another thread's parameters"
    );
}

/// A thread that pushed parameters and ended without submitting them (a recording abandoned on
/// an error) frees its slots: the ring is not held for the rest of the context's life.
#[test]
fn a_thread_that_ends_without_submitting_frees_its_slots() {
    let Some(ctx) = new_gpu_context() else { return };
    let ctx = ctx.with_uniform_ring_bytes(SMALL_RING);
    let target = storage_buffer(&ctx, "target", &[0u32; 4]);
    // A spawned thread, not a scoped one: `join` returns once the thread has run its
    // thread-local destructors, where a scope may end before them.
    let (abandoning, abandoned_target) = (ctx.clone(), target.clone());
    std::thread::spawn(move || drop(record_upload(&abandoning, 1, &abandoned_target)))
        .join()
        .expect("thread");
    assert_eq!(ctx.uniform_ring_open_threads(), 0);
    let before = ctx.host_costs.reading();
    for value in 0..4 * SMALL_RING as u32 / 16 {
        submit(&ctx, record_upload(&ctx, value, &target));
    }
    assert_eq!(
        ctx.host_costs.reading().since(&before).buffers_created,
        0,
        "every push found room in the ring"
    );
}

/// Two threads on one context with a profiler (two job slots on one GPU): a busy measure times
/// its own thread's passes only, and a second measure while it runs gets no reading instead of
/// resetting the first one's profile. Before stop 58 the other thread's pass was timed too, and
/// could still be unsubmitted when the measure read its timestamps back.
#[test]
fn a_busy_measure_times_its_own_threads_passes_only() {
    if gpu_context().is_none() {
        return;
    }
    let mut ctx = segsplat_gpu::GpuContext::new_default().expect("a context with a profiler");
    if let Err(error) = ctx.enable_kernel_profiling() {
        eprintln!("skipping: {error}");
        return;
    }
    let source = "@group(0) @binding(0) var<storage, read_write> input: array<u32>;\n\
                  @group(0) @binding(1) var<storage, read_write> output: array<u32>;\n\
                  @compute @workgroup_size(64) fn main(@builtin(global_invocation_id) id: vec3<u32>) {\n\
                      output[id.x] = input[id.x] + 1u;\n\
                  }";
    let kernel = Kernel::new(&ctx, "busy_probe", &[source], "main", &[]).expect("kernel");
    let dispatch_once = |from: &wgpu::Buffer, to: &wgpu::Buffer| {
        let mut encoder = new_encoder(&ctx);
        kernel.dispatch(&mut encoder, &kernel.bind(&ctx, &[from, to]), [4, 1, 1]);
        submit(&ctx, encoder);
    };
    let [a, b, c, d] = ["a", "b", "c", "d"].map(|label| storage_buffer(&ctx, label, &[0u32; 256]));
    let reading = segsplat_gpu::measure_busy(
        &ctx,
        2,
        2,
        |units| {
            for _ in 0..units {
                dispatch_once(&a, &b);
            }
            std::thread::scope(|scope| {
                scope.spawn(|| {
                    dispatch_once(&c, &d);
                    let nested = segsplat_gpu::measure_busy(&ctx, 1, 1, |_| Ok(()), |error| error);
                    assert!(
                        matches!(nested, Ok(None)),
                        "a second measure got {nested:?}"
                    );
                });
            });
            Ok(())
        },
        |error| error,
    )
    .expect("measure")
    .expect("a reading");
    assert_eq!(reading.timeline.passes, 2, "this thread's two passes alone");
    let timed: u32 = reading
        .profile
        .kernels
        .iter()
        .map(|kernel| kernel.passes)
        .sum();
    assert_eq!(timed, 2, "this thread's two dispatches alone");
}
