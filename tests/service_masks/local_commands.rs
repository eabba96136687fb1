//! The local commands on the data dir the service wrote: `segsplat export`, `eval --oracle`
//! (against a 3D-OVS folder made from the true masks) and `query`.

use segsplat_engine::ply::read_ply;
use segsplat_scene::Level;

use crate::common;
use crate::truth::true_mask;

fn segsplat(args: &[&str]) -> std::process::Output {
    std::process::Command::new(common::segsplat_bin::segsplat_bin())
        .args(args)
        .output()
        .unwrap()
}

/// `segsplat export`, `eval --oracle` (against a 3D-OVS folder made from the true masks) and
/// `query` on the data dir the service wrote.
pub(crate) fn local_commands_read_the_service_data(
    data_dir: &std::path::Path,
    scene_id: &str,
    files: &[(String, Vec<u8>)],
    cameras: &[serde_json::Value],
    middle_one_gaussians: usize,
) {
    let data = data_dir.to_str().unwrap();
    let work = tempfile::tempdir().unwrap();
    // `segsplat export` of the scene and object middle:1 into `folder`, in `format`.
    let export = |folder: &str, format: &str| {
        let dir = work.path().join(folder);
        let output = segsplat(&[
            "export",
            scene_id,
            "--data-dir",
            data,
            "--out",
            dir.to_str().unwrap(),
            "--object",
            "middle:1",
            "--format",
            format,
        ]);
        assert!(output.status.success(), "{output:?}");
        dir
    };
    let export_dir = export("export", "ply");
    for file in [
        "scene.ply",
        "labels.npy",
        "cameras.json",
        "objects.json",
        "metrics.json",
    ] {
        assert!(export_dir.join(file).is_file(), "{file}");
    }
    let object = std::fs::read(export_dir.join("middle-1.ply")).unwrap();
    assert_eq!(
        read_ply(object.as_slice()).unwrap().model.len(),
        middle_one_gaussians
    );
    let spz_dir = export("export-spz", "spz");
    assert!(!spz_dir.join("scene.ply").exists());
    for file in ["scene.spz", "middle-1.spz", "labels.npy"] {
        assert!(spz_dir.join(file).is_file(), "{file}");
    }
    let object = std::fs::read(spz_dir.join("middle-1.spz")).unwrap();
    let packed = spz_rs::load_packed_gaussians_from_spz_buffer(object.as_slice()).unwrap();
    assert_eq!(packed.num_points, middle_one_gaussians);
    let output = segsplat(&["export", scene_id, "--data-dir", data, "--object", "tiny:1"]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("small, middle or large"));

    // 3D-OVS layout: segmentations/classes.txt and <view>/<class>.png.
    let ground_truth = work.path().join("3d-ovs");
    let segmentations = ground_truth.join("segmentations");
    let classes = ["red ball", "green ball", "blue ball"];
    std::fs::create_dir_all(&segmentations).unwrap();
    std::fs::write(segmentations.join("classes.txt"), classes.join("\n")).unwrap();
    for frame_index in [2usize, 5, 9] {
        let name = cameras[frame_index]["name"].as_str().unwrap();
        let view = segmentations.join(std::path::Path::new(name).file_stem().unwrap());
        std::fs::create_dir_all(&view).unwrap();
        for (index, class) in classes.iter().enumerate() {
            let truth = true_mask(files, Level::Small, name, index as u32 + 1);
            if truth.area() == 0 {
                continue;
            }
            let png = image::GrayImage::from_fn(truth.width(), truth.height(), |x, y| {
                image::Luma([if truth.get(x, y) { 255 } else { 0 }])
            });
            png.save(view.join(format!("{class}.png"))).unwrap();
        }
    }
    let report_path = work.path().join("eval.json");
    let ground_truth = ground_truth.to_str().unwrap();
    let eval = |extra: &[&str]| {
        let mut args = vec!["eval", scene_id, "--data-dir", data];
        args.extend(["--ground-truth", ground_truth]);
        args.extend(extra);
        segsplat(&args)
    };
    let output = eval(&[
        "--oracle",
        "--visible",
        "--json",
        report_path.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{output:?}");
    println!("{stdout}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&report_path).unwrap()).unwrap();
    assert_eq!(report["format"], "3d_ovs");
    assert_eq!(report["selection"], "oracle");
    assert_eq!(report["segmentation"]["frame_count"], 3);
    let miou = report["segmentation"]["miou"].as_f64().unwrap();
    assert!(miou >= 0.65, "oracle mIoU {miou}: {report}");
    assert!(
        report["held_out"]["psnr"].as_f64().unwrap() > 10.0,
        "{report}"
    );

    // A LERF_OVS label of another capture (issue 41, item 5): refused, naming what does not
    // match, unless forced.
    let foreign = work.path().join("foreign-labels");
    std::fs::create_dir_all(&foreign).unwrap();
    let (width, height) = (
        cameras[2]["width"].as_u64().unwrap(),
        cameras[2]["height"].as_u64().unwrap(),
    );
    let label = serde_json::json!({
        "info": {"name": "other_capture_0042.jpg", "width": width, "height": height},
        "objects": [{
            "category": "red ball",
            "segmentation": [[0, 0], [width / 2, 0], [width / 2, height / 2], [0, height / 2]],
        }],
    });
    std::fs::write(
        foreign.join("frame_00003.json"),
        serde_json::to_vec(&label).unwrap(),
    )
    .unwrap();
    let foreign = foreign.to_str().unwrap();
    let foreign_eval = |extra: &[&str]| {
        let mut args = vec!["eval", scene_id, "--data-dir", data, "--oracle"];
        args.extend(["--ground-truth", foreign]);
        args.extend(extra);
        segsplat(&args)
    };
    let output = foreign_eval(&[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains("does not belong") && stderr.contains("other_capture_0042.jpg"),
        "{stderr}"
    );
    let output = foreign_eval(&["--force"]);
    assert!(output.status.success(), "{output:?}");

    // Without CLIP weights the language path says what to do instead.
    let output = eval(&[]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("--oracle"), "{stderr}");
    let output = segsplat(&["query", "no-such-scene", "red", "--data-dir", data]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("no scene"));
}
