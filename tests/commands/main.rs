//! The commands a person runs, run as a person runs them: the `segsplat` binary and the scripts
//! around it, a module per command.
//!
//! - [`quiet`]: `segsplat adapters` on a headless host prints no display noise;
//! - [`train_interrupt`]: `segsplat train` and Ctrl-C, a final checkpoint and `--resume`;
//! - [`demo_script`]: `scripts/demo.sh` end to end with an existing binary;
//! - [`gpu_check_script`]: `scripts/gpu_check.sh` without a GPU, over a stub pack;
//! - [`bin_lookup`]: which `segsplat` binary the tests run (`SEGSPLAT_BIN` or cargo's).

#[path = "../common/segsplat_bin.rs"]
mod segsplat_bin;

mod bin_lookup;
mod demo_script;
mod gpu_check_script;
mod quiet;
mod train_interrupt;
