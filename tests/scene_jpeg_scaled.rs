//! A large JPEG used at a small `max_resolution` never exists in memory at full size (issue 19
//! item 7): neither when the upload is validated nor when a job loads the frame. A counting
//! allocator (this test binary's own) records the largest single allocation.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{self, SyntheticImageFormat, SyntheticSpec};
use segsplat_scene::{LoadOptions, load_frame_rgb, load_scene, validate_scene};

struct LargestAllocation;

// The allocator interface is unsafe by nature; this forwards to the system allocator unchanged.

static LARGEST: AtomicUsize = AtomicUsize::new(0);

#[allow(unsafe_code)]
unsafe impl GlobalAlloc for LargestAllocation {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, pointer: *mut u8, layout: Layout) {
        unsafe { System.dealloc(pointer, layout) }
    }

    unsafe fn realloc(&self, pointer: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        unsafe { System.realloc(pointer, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: LargestAllocation = LargestAllocation;

#[test]
fn large_jpeg_frames_decode_near_the_size_used() {
    let (width, height) = (4000u32, 3000u32);
    let dir = tempfile::tempdir().unwrap();
    let spec = SyntheticSpec {
        width,
        height,
        frame_count: 2,
        image_format: SyntheticImageFormat::Jpeg,
        ..SyntheticSpec::default()
    };
    synthetic::write_colmap(dir.path(), &spec, ColmapEncoding::Binary).unwrap();
    let scene = load_scene(dir.path(), &LoadOptions::default()).unwrap();
    // One full-size 8-bit RGB frame is 36 MB; an eighth of each side is 0.6 MB (2.3 MB as
    // the float RGB the engine takes).
    let full_frame = (width * height * 3) as usize;

    LARGEST.store(0, Ordering::Relaxed);
    validate_scene(&scene).unwrap();
    let validating = LARGEST.load(Ordering::Relaxed);
    assert!(
        validating < full_frame / 8,
        "validation allocated {validating} bytes at once (a full frame is {full_frame})"
    );

    LARGEST.store(0, Ordering::Relaxed);
    let frame = load_frame_rgb(&scene, 0, Some(256)).unwrap();
    let loading = LARGEST.load(Ordering::Relaxed);
    assert_eq!(frame.dimensions(), (256, 192));
    assert!(
        loading < full_frame / 8,
        "loading at 256 allocated {loading} bytes at once (a full frame is {full_frame})"
    );
}
