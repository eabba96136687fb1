//! Real tools, where installed

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

use yaml_rust2::YamlLoader;

use crate::files::{list, text};
use crate::kubernetes::{kubernetes, kustomization, only_container, workload};

fn tool_works(program: &Path, args: &[&str]) -> bool {
    Command::new(program)
        .args(args)
        .output()
        .is_ok_and(|output| output.status.success())
}

/// Runs a tool that must succeed; its stdout.
fn run_ok(command: &mut Command, what: &str) -> String {
    let output = command.output().unwrap();
    assert!(
        output.status.success(),
        "{what} failed:\n{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
}

/// `kubernetes-validate` (PyPI; its schemas are in the package, no network), on PATH or where
/// docs/deploy.md installs it.
fn kubernetes_validate() -> Option<PathBuf> {
    let on_path = PathBuf::from("kubernetes-validate");
    if tool_works(&on_path, &["--version"]) {
        return Some(on_path);
    }
    let tools = std::env::var_os("SEGSPLAT_TOOLS_DIR")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME").map(|home| Path::new(&home).join(".cache/segsplat-tools"))
        })?;
    let installed = tools.join("kubernetes-validate/bin/kubernetes-validate");
    tool_works(&installed, &["--version"]).then_some(installed)
}

#[test]
fn kustomize_renders_the_overlay_and_the_schemas_accept_it() {
    let kubectl = Path::new("kubectl");
    if !tool_works(kubectl, &["version", "--client"]) {
        eprintln!("skipped: no kubectl to render the kustomizations (the checks above still ran)");
        return;
    }
    let overlay_dir = kubernetes("overlays/example");
    let overlay = kustomization(&overlay_dir);
    let namespace = text(&overlay["namespace"], "namespace");
    let image = &overlay["images"][0];
    let expected_image = format!(
        "{}:{}",
        text(&image["newName"], "newName"),
        text(&image["newTag"], "newTag")
    );
    let scratch = tempfile::tempdir().unwrap();
    for (name, dir) in [("base", kubernetes("base")), ("overlay", overlay_dir)] {
        let rendered = run_ok(
            Command::new(kubectl).arg("kustomize").arg(&dir),
            &format!("kubectl kustomize {}", dir.display()),
        );
        let objects = YamlLoader::load_from_str(&rendered).unwrap();
        assert!(objects.len() >= 9, "{name}: {} objects", objects.len());
        if name == "overlay" {
            let names: BTreeSet<String> = objects
                .iter()
                .filter(|object| matches!(object["kind"].as_str(), Some("ConfigMap" | "Secret")))
                .map(|object| text(&object["metadata"]["name"], "name"))
                .collect();
            for object in &objects {
                let kind = object["kind"].as_str().unwrap();
                if kind != "Namespace" {
                    assert_eq!(
                        object["metadata"]["namespace"].as_str(),
                        Some(namespace.as_str()),
                        "{kind}"
                    );
                }
                if matches!(kind, "Deployment" | "Job") {
                    let container = only_container(object);
                    assert_eq!(container["image"].as_str(), Some(expected_image.as_str()));
                    // Generated names carry a content hash; references follow it.
                    for source in list(&container["envFrom"], "envFrom") {
                        let reference = source["configMapRef"]["name"]
                            .as_str()
                            .or(source["secretRef"]["name"].as_str())
                            .unwrap();
                        assert!(names.contains(reference), "{reference} is rendered");
                    }
                }
            }
            let worker = workload(&objects, "worker");
            assert!(worker["spec"]["replicas"].as_i64().is_some());
        }
        let Some(validator) = kubernetes_validate() else {
            eprintln!("skipped: no kubernetes-validate to check {name} against the schemas");
            continue;
        };
        let file = scratch.path().join(format!("{name}.yaml"));
        std::fs::write(&file, rendered).unwrap();
        run_ok(
            Command::new(&validator)
                .args(["--strict", "--quiet"])
                .arg(&file),
            &format!("{name} against the Kubernetes schemas"),
        );
    }
}
