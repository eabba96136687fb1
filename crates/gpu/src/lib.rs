//! GPU foundation: adapter discovery, device creation, and (in their own files) the generic compute
//! primitives the engine is built from. Knows nothing of splats, HTTP or databases.

// No `unwrap()` outside tests: input, I/O and GPU failures become errors that name the
// problem (an invariant the code relies on says why in an `expect`).
#![cfg_attr(not(test), deny(clippy::unwrap_used))]

pub mod bind_cache;
pub mod context;
pub mod deferred_read;
pub mod encoder;
pub mod host_costs;
pub mod kernel;
pub mod kernel_cache;
pub mod kernel_choices;
pub mod kernel_layout;
pub mod pass_timeline;
pub mod profiler;
pub mod release;
pub mod scan;
pub mod snapshot_copies;
pub mod sort;
pub mod uniform_ring;
pub mod validation;

pub use context::{AdapterFilter, AdapterReport, GpuContext, GpuError};
pub use encoder::Encoder;
pub use host_costs::{HostCostReading, HostCosts, dispatches_on_this_thread};
pub use kernel::{Binding, Bound, Kernel};
pub use kernel_cache::KernelCompiles;
pub use kernel_choices::{GemmLayout, KernelChoices, RasterLayout};
pub use pass_timeline::PassTimeline;
pub use profiler::{BusyReading, BusySummary, KernelProfile, KernelProfiler, measure_busy};
pub use release::{release_context, sole_owner};
pub use scan::{ExclusiveScan, WorkgroupSum};
pub use sort::{DEFAULT_SMALL_SORT_LIMIT, RadixSort};
pub use uniform_ring::UniformParams;
