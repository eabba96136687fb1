//! `segsplat train` and Ctrl-C: the first interrupt stops at the next step boundary, writes a
//! final checkpoint, says where it is and how to resume, and exits 130; `--resume` then starts
//! from that checkpoint's step.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use segsplat_engine::checkpoint::Checkpoint;
use segsplat_engine::train::TrainerMeta;
use segsplat_scene::colmap::ColmapEncoding;
use segsplat_scene::synthetic::{SyntheticSpec, write_colmap};

use crate::segsplat_bin;

/// Starts `segsplat train` with `extra` flags and returns it once its Ctrl-C handler is in
/// place (it says so on stderr), with the rest of stderr arriving on the receiver.
fn start_training(
    dataset: &Path,
    out: &Path,
    extra: &[&str],
) -> (Child, String, mpsc::Receiver<String>) {
    let mut child = Command::new(segsplat_bin::segsplat_bin())
        .arg("train")
        .arg(dataset)
        .arg("--out")
        .arg(out)
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting segsplat train");
    let stderr = child.stderr.take().expect("piped stderr");
    let (lines, receiver) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if lines.send(line).is_err() {
                break;
            }
        }
    });
    loop {
        match receiver.recv_timeout(Duration::from_secs(300)) {
            Ok(line) if line.contains("Ctrl-C stops with a checkpoint") => {
                return (child, line, receiver);
            }
            Ok(_) => {}
            Err(error) => {
                let _ = child.kill();
                let _ = child.wait();
                panic!("segsplat train never said it started training: {error}");
            }
        }
    }
}

fn interrupt(child: &Child) {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("running kill");
    assert!(status.success());
}

#[test]
fn ctrl_c_writes_a_final_checkpoint_and_says_how_to_resume() {
    let dir = tempfile::tempdir().unwrap();
    let dataset = dir.path().join("dataset");
    let spec = SyntheticSpec {
        frame_count: 6,
        width: 32,
        height: 24,
        ..SyntheticSpec::default()
    };
    write_colmap(&dataset, &spec, ColmapEncoding::Text).unwrap();
    let out = dir.path().join("out");
    // Far more steps than the test waits for, and no periodic checkpoints: the only checkpoint
    // can be the one the interrupt writes.
    let steps = ["--steps", "1000000", "--checkpoint-every", "0"];
    let (mut child, started, rest) = start_training(&dataset, &out, &steps);
    assert!(started.contains("steps 0..1000000"), "{started}");
    std::thread::sleep(Duration::from_secs(2));
    interrupt(&child);
    let status = child.wait().unwrap();
    let said: Vec<String> = rest.try_iter().collect();
    let said = said.join("\n");
    assert_eq!(status.code(), Some(130), "{said}");
    let checkpoint_path = out.join("train.ckpt");
    let checkpoint = Checkpoint::<TrainerMeta>::load(&checkpoint_path).expect("a final checkpoint");
    let step = checkpoint.meta.step;
    assert!(step > 0 && step < 1_000_000, "step {step}");
    assert!(
        said.contains(&format!("stopped at step {step} of 1000000")),
        "{said}"
    );
    assert!(
        said.contains(&checkpoint_path.display().to_string()),
        "{said}"
    );
    assert!(said.contains("--resume"), "{said}");

    // Resuming starts at the checkpoint's step (and is interruptible again).
    let (mut child, started, _rest) = start_training(&dataset, &out, &["--resume"]);
    assert!(
        started.contains(&format!("steps {step}..1000000")),
        "{started}"
    );
    interrupt(&child);
    assert_eq!(child.wait().unwrap().code(), Some(130));
    let resumed = Checkpoint::<TrainerMeta>::load(&checkpoint_path).unwrap();
    assert!(resumed.meta.step >= step);
}
