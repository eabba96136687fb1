//! Which `segsplat` binary the tests run. Cargo bakes the path of the binary it built into each
//! test binary (`CARGO_BIN_EXE_segsplat`), and that path exists only on the machine that built
//! them; test binaries carried to another machine (`scripts/gpu_check.sh run`, on a GPU host with
//! no toolchain) are told where the binary is there by `SEGSPLAT_BIN`. Included by `#[path]` from
//! the tests that run the CLI, so it needs none of the heavier shared modules.

use std::ffi::OsString;
use std::path::PathBuf;

/// The variable that names the binary to run instead of cargo's.
pub const SEGSPLAT_BIN: &str = "SEGSPLAT_BIN";

/// `SEGSPLAT_BIN` when it is set and not empty, else the binary cargo built with this test.
pub fn segsplat_bin() -> PathBuf {
    resolve(
        std::env::var_os(SEGSPLAT_BIN),
        env!("CARGO_BIN_EXE_segsplat"),
    )
}

/// The choice [`segsplat_bin`] makes, apart from the process environment so tests can give it
/// any value. A set variable that names no file panics rather than falling back: falling back
/// would run a stale build, or fail later with a bare "No such file" that names nothing.
pub fn resolve(variable: Option<OsString>, built: &str) -> PathBuf {
    let Some(named) = variable.filter(|value| !value.is_empty()) else {
        return PathBuf::from(built);
    };
    let path = PathBuf::from(&named);
    assert!(
        path.is_file(),
        "{SEGSPLAT_BIN}={} is set but names no file (unset it to run the binary cargo built, {built})",
        path.display()
    );
    // Absolute, so children started in another directory (tests set `current_dir`) find it too.
    std::fs::canonicalize(&path).unwrap_or(path)
}
