//! What can be checked of the container image without building it (no base image can be pulled
//! on these machines): the Dockerfile's `SEGSPLAT_*` variables are configuration keys the
//! service accepts, its exposed ports are the ones they set, the binary it copies is the one
//! cargo builds, and its commands are `segsplat` subcommands.

use std::collections::BTreeMap;
use std::path::Path;

fn dockerfile() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/docker/Dockerfile");
    std::fs::read_to_string(&path).unwrap_or_else(|error| panic!("{}: {error}", path.display()))
}

/// The Dockerfile's instructions, continuation lines joined, comments dropped.
fn instructions(text: &str) -> Vec<(String, String)> {
    let mut joined = Vec::new();
    let mut current = String::new();
    for line in text.lines() {
        let trimmed = line.trim();
        if trimmed.starts_with('#') || trimmed.is_empty() && current.is_empty() {
            continue;
        }
        if let Some(head) = trimmed.strip_suffix('\\') {
            current.push_str(head);
            current.push(' ');
            continue;
        }
        current.push_str(trimmed);
        if let Some((keyword, rest)) = current.split_once(' ') {
            joined.push((keyword.to_string(), rest.trim().to_string()));
        }
        current.clear();
    }
    joined
}

fn env_vars(instructions: &[(String, String)]) -> BTreeMap<String, String> {
    instructions
        .iter()
        .filter(|(keyword, _)| keyword == "ENV")
        .flat_map(|(_, rest)| rest.split_whitespace())
        .filter_map(|pair| pair.split_once('='))
        .map(|(name, value)| (name.to_string(), value.to_string()))
        .collect()
}

#[test]
fn the_images_settings_are_the_services() {
    let instructions = instructions(&dockerfile());
    let env = env_vars(&instructions);
    let segsplat_vars: Vec<(String, String)> = env
        .iter()
        .filter(|(name, _)| name.starts_with("SEGSPLAT_"))
        .map(|(name, value)| (name.clone(), value.clone()))
        .collect();
    assert!(segsplat_vars.len() >= 4, "{segsplat_vars:?}");
    let config = segsplat_service::config::Config::load(
        None,
        segsplat_vars,
        &segsplat_service::config::ConfigOverrides::default(),
    )
    .expect("the image's SEGSPLAT_* variables are valid configuration");
    config.validate().unwrap();
    assert_eq!(config.data_dir, Path::new("/data"));
    assert!(
        config.http_addr.ip().is_unspecified(),
        "reachable from outside the container"
    );

    let exposed: Vec<u16> = instructions
        .iter()
        .filter(|(keyword, _)| keyword == "EXPOSE")
        .flat_map(|(_, rest)| rest.split_whitespace())
        .map(|port| port.parse().unwrap())
        .collect();
    assert_eq!(
        exposed,
        vec![
            config.http_addr.port(),
            config.grpc_addr.port(),
            config.workers.ops_addr.port()
        ]
    );
    // The NVIDIA runtime exposes the Vulkan driver only with `graphics`.
    assert!(
        env["NVIDIA_DRIVER_CAPABILITIES"]
            .split(',')
            .any(|capability| capability == "graphics"),
        "{env:?}"
    );
    assert!(env.contains_key("ORT_DYLIB_PATH"));
}

#[test]
fn the_images_binary_and_commands_exist() {
    let instructions = instructions(&dockerfile());
    assert!(
        instructions.iter().any(|(keyword, rest)| keyword == "COPY"
            && rest.contains("/src/target/release/segsplat /usr/local/bin/segsplat")),
        "the release binary is copied"
    );
    let command = |keyword: &str| -> Vec<String> {
        let (_, rest) = instructions
            .iter()
            .find(|(found, _)| found == keyword)
            .unwrap_or_else(|| panic!("no {keyword}"));
        serde_json::from_str(rest).unwrap()
    };
    assert_eq!(command("ENTRYPOINT"), vec!["segsplat"]);
    for subcommand in [command("CMD")[0].as_str(), "worker"] {
        let output = std::process::Command::new(crate::common::segsplat_bin::segsplat_bin())
            .args([subcommand, "--help"])
            .output()
            .unwrap();
        assert!(output.status.success(), "segsplat {subcommand} --help");
    }
}
