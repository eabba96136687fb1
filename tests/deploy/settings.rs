//! Configuration

use std::collections::BTreeSet;
use std::process::Command;

use segsplat_service::config::{Config, ConfigOverrides};

use crate::files::{read, repo};

/// Dotted paths of every configuration key, and of those that default to null (an unset
/// `Option`, whose value may be a whole table).
fn config_keys() -> (BTreeSet<String>, BTreeSet<String>) {
    fn walk(
        value: &serde_json::Value,
        path: &str,
        keys: &mut BTreeSet<String>,
        nulls: &mut BTreeSet<String>,
    ) {
        if !path.is_empty() {
            keys.insert(path.to_string());
        }
        match value {
            serde_json::Value::Object(fields) => {
                for (name, field) in fields {
                    let child = if path.is_empty() {
                        name.clone()
                    } else {
                        format!("{path}.{name}")
                    };
                    walk(field, &child, keys, nulls);
                }
            }
            serde_json::Value::Null => {
                nulls.insert(path.to_string());
            }
            _ => {}
        }
    }
    let defaults = serde_json::to_value(Config::default()).unwrap();
    let mut keys = BTreeSet::new();
    let mut nulls = BTreeSet::new();
    walk(&defaults, "", &mut keys, &mut nulls);
    (keys, nulls)
}

/// `Config::load` ignores variables whose first segment is no top-level key (they belong to
/// other tools), so a misspelt section would pass silently; this names the key exactly.
fn assert_config_key(variable: &str, place: &str) {
    let (keys, nulls) = config_keys();
    let path = variable
        .strip_prefix("SEGSPLAT_")
        .unwrap()
        .split("__")
        .map(str::to_lowercase)
        .collect::<Vec<_>>()
        .join(".");
    let under_unset_section = nulls
        .iter()
        .any(|null| path.starts_with(&format!("{null}.")));
    assert!(
        keys.contains(&path) || under_unset_section,
        "{place}: {variable} is not a configuration key ({path})"
    );
}

/// Variables other than `SEGSPLAT_*` that the segsplat processes read.
const OTHER_VARIABLES: [&str; 6] = [
    "AWS_ACCESS_KEY_ID",
    "AWS_SECRET_ACCESS_KEY",
    "AWS_SESSION_TOKEN",
    "AWS_REGION",
    "AWS_DEFAULT_REGION",
    "AWS_ENDPOINT",
];

/// Checks a segsplat container's environment and loads the configuration it makes.
pub(crate) fn load_environment(environment: &[(String, String)], place: &str) -> Config {
    for (name, _) in environment {
        if name.starts_with("SEGSPLAT_") {
            assert_config_key(name, place);
        } else {
            assert!(
                OTHER_VARIABLES.contains(&name.as_str()),
                "{place}: {name} is read by nothing in segsplat"
            );
        }
    }
    let segsplat: Vec<(String, String)> = environment
        .iter()
        .filter(|(name, _)| name.starts_with("SEGSPLAT_"))
        .cloned()
        .collect();
    Config::load(None, segsplat, &ConfigOverrides::default())
        .unwrap_or_else(|error| panic!("{place}: the settings do not load: {error}"))
}

// ---------------------------------------------------------------------------------------------
// The binary's commands and the service's routes

/// `segsplat SUBCOMMAND --help`, so that every flag a deploy file passes is one the binary has.
pub(crate) fn assert_command_exists(args: &[String], place: &str) {
    let subcommand = args
        .first()
        .unwrap_or_else(|| panic!("{place}: no subcommand"));
    let output = Command::new(crate::common::segsplat_bin::segsplat_bin())
        .args([subcommand.as_str(), "--help"])
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{place}: `segsplat {subcommand}` does not exist"
    );
    let help = String::from_utf8(output.stdout).unwrap();
    for flag in args.iter().skip(1).filter(|arg| arg.starts_with("--")) {
        let name = flag.split('=').next().unwrap_or(flag);
        assert!(
            help.split(|c: char| c.is_whitespace() || c == ',')
                .any(|word| word == name),
            "{place}: `segsplat {subcommand}` has no {name}:\n{help}"
        );
    }
}

/// The probe paths are routes of both listeners: the API's REST router and a worker process's
/// ops router (`crates/api/src/router.rs`).
#[test]
fn probe_paths_are_routes_of_the_api_and_the_worker() {
    let source = read(&repo().join("crates/api/src/router.rs"));
    let (api, ops) = source
        .split_once("pub fn ops_router")
        .expect("the worker's ops router");
    for path in ["/healthz", "/readyz", "/metrics"] {
        let route = format!(".route(\"{path}\"");
        assert!(api.contains(&route), "the API serves {path}");
        assert!(ops.contains(&route), "a worker process serves {path}");
    }
}
