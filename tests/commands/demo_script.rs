//! `scripts/demo.sh` as a person runs it, with an existing binary (`SEGSPLAT_BIN`): a progress
//! bar per stage (the segmentation stage counting views), no line printed twice in a row, no
//! colour codes or raw dicts, the server's log in a file, a summary table with each stage's time,
//! and every output in the one folder it names (nothing in the repository).

use std::process::Command;

use crate::segsplat_bin;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free port")
}

#[test]
fn the_demo_walks_through_the_job_cleanly() {
    let work = tempfile::tempdir().unwrap();
    let dataset = work.path().join("dataset");
    let made = Command::new(segsplat_bin::segsplat_bin())
        .arg("synthetic-scene")
        .arg(&dataset)
        .output()
        .unwrap();
    assert!(made.status.success(), "{made:?}");
    let out = work.path().join("demo-output");
    let repo = env!("CARGO_MANIFEST_DIR");
    let run = Command::new("bash")
        .arg(format!("{repo}/scripts/demo.sh"))
        .arg(&dataset)
        .arg("40")
        .env("SEGSPLAT_BIN", segsplat_bin::segsplat_bin())
        .env("SEGSPLAT_DEMO_OUT", &out)
        .env("SEGSPLAT_DEMO_PORT", free_port().to_string())
        .current_dir(work.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stdout}\n{stderr}");
    assert!(!stdout.contains('\u{1b}'), "colour codes: {stdout}");
    assert!(!stdout.contains("{'"), "a raw Python dict: {stdout}");
    let lines: Vec<&str> = stdout.lines().collect();
    for pair in lines.windows(2) {
        assert!(
            pair[0].is_empty() || pair[0] != pair[1],
            "printed twice: {}",
            pair[0]
        );
    }
    assert!(
        lines
            .iter()
            .any(|line| line.starts_with("segment") && line.contains("views")),
        "{stdout}"
    );
    assert!(
        lines
            .iter()
            .any(|line| line.starts_with("train") && line.contains("40/40 steps")),
        "{stdout}"
    );
    for heading in ["Objects found", "Summary", "held-out PSNR"] {
        assert!(stdout.contains(heading), "{heading}: {stdout}");
    }
    // Where the job's time went, stage by stage in the order they ran.
    let stage_times = lines
        .iter()
        .find(|line| line.starts_with("stage times"))
        .unwrap_or_else(|| panic!("no stage times row: {stdout}"));
    let segment = stage_times
        .find("segment ")
        .expect("the segment stage's time");
    let train = stage_times.find("train ").expect("the train stage's time");
    assert!(segment < train, "{stage_times}");
    // The frames held out of training are named before their bars (the synthetic scene
    // holds out every 8th of its frames).
    assert!(
        lines
            .iter()
            .any(|line| line.contains("frames train;") && line.contains("held out")),
        "{stdout}"
    );
    // Without a CLIP model the embed stage says it is skipped, not a bar stuck at 0/1.
    assert!(
        !lines
            .iter()
            .any(|line| line.starts_with("embed") && line.contains("0/1")),
        "a stalled bar: {stdout}"
    );
    assert!(
        lines
            .iter()
            .any(|line| line.starts_with("embed") && line.contains("skipped: no CLIP model")),
        "{stdout}"
    );
    // How to look at the result, and the server's stop said out loud.
    assert!(stdout.contains("/#/scenes/"), "{stdout}");
    assert!(stdout.contains("SEGSPLAT_DEMO_KEEP_SERVER=1"), "{stdout}");
    for file in ["server.log", "summary.txt", "objects.json"] {
        assert!(out.join(file).is_file(), "{file}");
    }
    let log = std::fs::read_to_string(out.join("server.log")).unwrap();
    assert!(
        log.contains("segsplat") || !log.is_empty(),
        "empty server log"
    );
    assert!(!log.contains('\u{1b}'), "colour codes in the log file");
    // The job's warnings reach the walk-through, not only the server's log.
    if log.contains("densification never runs") {
        assert!(
            stdout.contains("warning: densification never runs"),
            "{stdout}"
        );
    }
    let masks: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(Result::ok)
        .filter(|entry| {
            entry
                .file_name()
                .to_string_lossy()
                .starts_with("mask_large_")
        })
        .collect();
    assert_eq!(masks.len(), 1, "one mask PNG in the output folder");
    // Nothing left where it was run from, but the dataset and the output folder.
    let mut left: Vec<String> = std::fs::read_dir(work.path())
        .unwrap()
        .filter_map(Result::ok)
        .map(|entry| entry.file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, ["dataset", "demo-output"]);
}

#[test]
fn the_demo_refuses_steps_that_are_neither_a_number_nor_defaults() {
    let work = tempfile::tempdir().unwrap();
    let repo = env!("CARGO_MANIFEST_DIR");
    let run = Command::new("bash")
        .arg(format!("{repo}/scripts/demo.sh"))
        .arg(work.path())
        .arg("500x")
        .env("SEGSPLAT_BIN", segsplat_bin::segsplat_bin())
        .env("SEGSPLAT_DEMO_OUT", work.path().join("demo-output"))
        .current_dir(work.path())
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2), "{run:?}");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("STEPS") && stderr.contains("500x"),
        "{stderr}"
    );
    assert!(!work.path().join("demo-output").exists(), "nothing written");
}
