//! Shared set-up for the GPU kernel tests (`tests/gpu_*.rs`): one adapter context per test binary
//! and buffer helpers.
#![allow(dead_code)]

#[path = "../common/segsplat_bin.rs"]
pub mod segsplat_bin;

use std::sync::OnceLock;

use segsplat_gpu::GpuContext;
use wgpu::util::DeviceExt;

/// A context of the test's own on the default adapter, or `None` (with a printed reason) when no
/// adapter exists and `SEGSPLAT_SKIP_GPU_TESTS=1` allows skipping. Without that variable a
/// missing adapter fails.
pub fn new_gpu_context() -> Option<GpuContext> {
    log_to_stderr_when_asked();
    match GpuContext::new_default() {
        Ok(ctx) => Some(ctx),
        Err(error) if std::env::var("SEGSPLAT_SKIP_GPU_TESTS").as_deref() == Ok("1") => {
            eprintln!("skipping GPU test: no adapter ({error})");
            None
        }
        Err(error) => panic!("no GPU adapter (set SEGSPLAT_SKIP_GPU_TESTS=1 to skip): {error}"),
    }
}

/// One context shared by the test binary's tests ([`new_gpu_context`] made once).
pub fn gpu_context() -> Option<&'static GpuContext> {
    static CONTEXT: OnceLock<Option<GpuContext>> = OnceLock::new();
    CONTEXT.get_or_init(new_gpu_context).as_ref()
}

/// A clone of [`gpu_context`] (its kernel cache shared), for tests that change what the context
/// reports, and for binaries whose tests each made a device before: each kernel then compiles
/// once. With a device per test, `raster_gpu` compiled every kernel eleven times at once and ran
/// past its 30 s on the H200 with 7 of 11 tests left (stop 54), while the binaries sharing one
/// context finished in time.
pub fn shared_gpu_context() -> Option<GpuContext> {
    gpu_context().cloned()
}

/// Parameter slots in the uniform ring of [`small_ring_gpu_context`].
pub const SMALL_RING_SLOTS: u64 = 16;

/// One context shared by the test binary's tests whose uniform ring holds only
/// [`SMALL_RING_SLOTS`] kernel parameters, so the binary's parallel tests go round it all the
/// time: a recording whose parameters another thread could overwrite before it is submitted
/// then reads wrong ones (`deform_gpu`'s wrong products on the H200 at stop 54). Pushes the
/// ring cannot take get buffers of their own, so a test that counts buffers uses
/// [`gpu_context`].
pub fn small_ring_gpu_context() -> Option<&'static GpuContext> {
    static CONTEXT: OnceLock<Option<GpuContext>> = OnceLock::new();
    CONTEXT
        .get_or_init(|| {
            let ctx = new_gpu_context()?;
            // The largest kernel parameters are under 256 bytes, and a slot is aligned.
            let slot = 256u64.max(u64::from(ctx.limits.min_uniform_buffer_offset_alignment));
            Some(ctx.with_uniform_ring_bytes(SMALL_RING_SLOTS * slot))
        })
        .as_ref()
}

/// With `RUST_LOG` set, log records (wgpu's among them) go to stderr, where the test harness
/// does not hide them: `scripts/sync_validation.sh` runs the GPU tests under the Khronos
/// validation layer, whose findings wgpu reports only through `log`.
fn log_to_stderr_when_asked() {
    static INSTALLED: std::sync::Once = std::sync::Once::new();
    INSTALLED.call_once(|| {
        let Ok(filter) = tracing_subscriber::EnvFilter::try_from_default_env() else {
            return;
        };
        // Another logger already installed is as good.
        let _ = tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(std::io::stderr)
            .try_init();
    });
}

/// A storage buffer holding `data`, readable back by the tests.
pub fn storage_buffer<T: bytemuck::Pod>(ctx: &GpuContext, label: &str, data: &[T]) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    if bytes.is_empty() {
        return ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: 16,
            usage: usage(),
            mapped_at_creation: false,
        });
    }
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage: usage(),
        })
}

fn usage() -> wgpu::BufferUsages {
    wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST
}

pub fn new_encoder(ctx: &GpuContext) -> segsplat_gpu::Encoder {
    segsplat_gpu::Encoder::new(ctx, "test")
}

pub fn submit(ctx: &GpuContext, encoder: segsplat_gpu::Encoder) {
    ctx.submit(encoder.finish());
}

pub fn seeded_rng(seed: u64) -> rand_chacha::ChaCha8Rng {
    use rand::SeedableRng;
    rand_chacha::ChaCha8Rng::seed_from_u64(seed)
}

/// Runs the `segsplat` binary ([`segsplat_bin`]) with `args` (CLI tests of `train`, `bench`,
/// `synthetic-scene`).
pub fn segsplat(args: &[&str]) -> std::process::Output {
    std::process::Command::new(segsplat_bin::segsplat_bin())
        .args(args)
        .output()
        .expect("run segsplat")
}

/// Writes a synthetic scene into `dir/name` with `segsplat synthetic-scene` (`flags` as on its
/// command line: frames, size, `--dynamic`) and returns the scene's path.
pub fn write_synthetic_scene(dir: &std::path::Path, name: &str, flags: &[&str]) -> String {
    let scene = dir.join(name).to_str().expect("utf-8 path").to_string();
    let written = segsplat(&[&["synthetic-scene", scene.as_str()], flags].concat());
    assert!(written.status.success(), "{written:?}");
    scene
}

/// Runs `steps` more steps of `trainer` and asserts that they created no buffer and no bind
/// group on `ctx` (a context of the test's own: a shared one counts other tests' work too).
pub fn assert_steps_allocate_nothing(
    ctx: &GpuContext,
    trainer: &mut segsplat_engine::train::Trainer,
    steps: u32,
) {
    let before = ctx.host_costs.reading();
    let until = trainer.step() + steps;
    trainer.run_until(until, |_| true).expect("train");
    let during = ctx.host_costs.reading().since(&before);
    eprintln!(
        "{steps} steady steps: {} bind groups and {} buffers created",
        during.bind_groups_created, during.buffers_created
    );
    assert_eq!(during.bind_groups_created, 0);
    assert_eq!(during.buffers_created, 0);
}

/// Takes `trainer`'s checkpoint the job's way ([`Trainer::checkpoint_snapshot`]: GPU copies,
/// finished on another thread after `more_steps` further steps) and asserts that it equals the
/// blocking [`Trainer::checkpoint`] taken at the same step, bit for bit; that taking it read
/// nothing back and waited for nothing on this thread; and that a second snapshot reuses the
/// first one's staging buffers. `ctx` should be the trainer's own context (a shared one counts
/// other tests' work too).
pub fn assert_snapshot_equals_checkpoint(
    ctx: &GpuContext,
    trainer: &mut segsplat_engine::train::Trainer,
    more_steps: u32,
) {
    use segsplat_gpu::snapshot_copies::CopyStaging;
    let blocking = trainer.checkpoint().expect("blocking checkpoint");
    let before = ctx.host_costs.reading();
    let pending = trainer
        .checkpoint_snapshot(CopyStaging::new())
        .expect("snapshot");
    let taken = ctx.host_costs.reading().since(&before);
    assert_eq!(
        (taken.read_backs, taken.bytes_read_back, taken.wait_nanos),
        (0, 0, 0),
        "the snapshot read back or waited on the loop's thread: {taken:?}"
    );
    assert_eq!(pending.step(), trainer.step());
    // The trainer moves on before the copies are read: the snapshot keeps its step's state.
    let until = trainer.step() + more_steps;
    trainer.run_until(until, |_| true).expect("train on");
    let (snapshot, staging) = std::thread::spawn(move || pending.finish())
        .join()
        .expect("writer thread")
        .expect("finish the snapshot");
    assert_eq!(snapshot.sections, blocking.sections, "arrays differ");
    assert_eq!(
        serde_json::to_value(&snapshot.meta).expect("meta"),
        serde_json::to_value(&blocking.meta).expect("meta"),
    );
    let before = ctx.host_costs.reading();
    let again = trainer.checkpoint_snapshot(staging).expect("snapshot");
    let taken = ctx.host_costs.reading().since(&before);
    assert_eq!(
        taken.buffers_created, 0,
        "the staging buffers were not reused"
    );
    let (again, _) = again.finish().expect("finish the snapshot");
    assert_eq!(
        again.sections,
        trainer.checkpoint().expect("checkpoint").sections
    );
}
