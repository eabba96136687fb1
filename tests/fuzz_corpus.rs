//! The fuzz targets on stable Rust: every committed corpus file (seeds and the inputs that once
//! crashed a parser) goes through every target function, so a regression shows on machines
//! without nightly or cargo-fuzz. See docs/fuzzing.md.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use segsplat_scene::fuzz_entry::TARGETS;

/// One input may take this long before it counts as a hang (debug build, shared CI machine).
const SLOW_INPUT: Duration = Duration::from_secs(20);

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz")
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .flatten()
                .map(|entry| entry.path())
                .filter(|path| path.is_file())
                .collect()
        })
        .unwrap_or_default();
    files.sort();
    files
}

#[test]
fn every_corpus_file_runs_through_every_target() {
    let mut replayed = 0;
    for (corpus_name, _) in TARGETS {
        let corpus = files_in(&fuzz_dir().join("corpus").join(corpus_name));
        assert!(!corpus.is_empty(), "fuzz/corpus/{corpus_name} has no seeds");
        for file in corpus {
            let bytes = std::fs::read(&file).unwrap();
            for (target, run) in TARGETS {
                let started = Instant::now();
                run(&bytes);
                assert!(
                    started.elapsed() < SLOW_INPUT,
                    "{target} took {:?} on {}",
                    started.elapsed(),
                    file.display()
                );
                replayed += 1;
            }
        }
    }
    eprintln!("replayed {replayed} corpus inputs");
}

/// `fuzz/fuzz_targets/` and [`TARGETS`] name the same targets, so CI's bounded runs and this
/// replay cover the same parsers.
#[test]
fn fuzz_targets_match_the_library_list() {
    let mut on_disk: Vec<String> = files_in(&fuzz_dir().join("fuzz_targets"))
        .iter()
        .filter_map(|path| Some(path.file_stem()?.to_str()?.to_string()))
        .collect();
    on_disk.sort();
    let mut listed: Vec<String> = TARGETS.iter().map(|(name, _)| name.to_string()).collect();
    listed.sort();
    assert_eq!(on_disk, listed);
}
