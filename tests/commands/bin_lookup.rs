//! The tests' binary lookup (`tests/common/segsplat_bin.rs`): `SEGSPLAT_BIN` wins when it names a
//! file, a set variable naming nothing fails loudly, and an unset or empty one falls back to the
//! binary cargo built. The environment is read in a child process (this test binary run again
//! on its ignored `reports_the_binary`), since changing this process's environment is unsafe.

use std::ffi::OsString;
use std::process::Command;

use crate::segsplat_bin::{SEGSPLAT_BIN, resolve, segsplat_bin};

const BUILT: &str = "/nowhere/target/release/segsplat";

#[test]
fn an_unset_or_empty_variable_means_the_binary_cargo_built() {
    assert_eq!(resolve(None, BUILT), std::path::Path::new(BUILT));
    assert_eq!(
        resolve(Some(OsString::new()), BUILT),
        std::path::Path::new(BUILT)
    );
}

#[test]
fn a_variable_naming_a_file_wins_and_is_made_absolute() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("segsplat");
    std::fs::write(&file, "").unwrap();
    let chosen = resolve(Some(file.clone().into_os_string()), BUILT);
    assert_eq!(chosen, std::fs::canonicalize(&file).unwrap());
}

#[test]
#[should_panic(expected = "SEGSPLAT_BIN=/nowhere/segsplat is set but names no file")]
fn a_variable_naming_no_file_panics_naming_the_variable() {
    resolve(Some("/nowhere/segsplat".into()), BUILT);
}

/// What [`segsplat_bin`] chooses in this process's environment; run by the test below.
#[test]
#[ignore = "run in a child process by the_process_environment_is_honoured"]
fn reports_the_binary() {
    println!("chosen binary: [{}]", segsplat_bin().display());
}

fn chosen_in_child(variable: Option<&std::path::Path>) -> std::process::Output {
    let mut child = Command::new(std::env::current_exe().unwrap());
    child.args([
        "--exact",
        "bin_lookup::reports_the_binary",
        "--ignored",
        "--nocapture",
    ]);
    match variable {
        Some(path) => child.env(SEGSPLAT_BIN, path),
        None => child.env_remove(SEGSPLAT_BIN),
    };
    child.output().unwrap()
}

#[test]
fn the_process_environment_is_honoured() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("segsplat-elsewhere");
    std::fs::write(&file, "").unwrap();
    let named = chosen_in_child(Some(&file));
    let stdout = String::from_utf8_lossy(&named.stdout);
    let expected = std::fs::canonicalize(&file).unwrap();
    assert!(named.status.success(), "{named:?}");
    assert!(
        stdout.contains(&format!("chosen binary: [{}]", expected.display())),
        "{stdout}"
    );

    let unset = chosen_in_child(None);
    let stdout = String::from_utf8_lossy(&unset.stdout);
    assert!(
        stdout.contains(&format!(
            "chosen binary: [{}]",
            env!("CARGO_BIN_EXE_segsplat")
        )),
        "{stdout}"
    );

    let missing = chosen_in_child(Some(&dir.path().join("absent")));
    let output = String::from_utf8_lossy(&missing.stderr);
    assert!(!missing.status.success(), "{missing:?}");
    assert!(output.contains("SEGSPLAT_BIN="), "{output}");
}
