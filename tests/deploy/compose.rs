//! Compose

use std::collections::{BTreeMap, BTreeSet};

use yaml_rust2::Yaml;
use yaml_rust2::yaml::Hash;

use crate::files::{deploy, env_file, list, read, repo, scalar, single_document, strings, text};
use crate::settings::{assert_command_exists, load_environment};

/// Compose's variable substitution with each variable's default (`${NAME:-default}`, `$$`),
/// applied to values as compose does; returns the variables named.
fn substitute(value: &str, variables: &mut BTreeSet<String>) -> String {
    let mut out = String::new();
    let mut rest = value;
    while let Some(start) = rest.find('$') {
        out.push_str(&rest[..start]);
        let tail = &rest[start + 1..];
        if let Some(after) = tail.strip_prefix('$') {
            out.push('$');
            rest = after;
        } else if let Some(inner) = tail.strip_prefix('{') {
            let end = inner
                .find('}')
                .unwrap_or_else(|| panic!("unclosed ${{ in {value}"));
            let (name, default) = inner[..end].split_once(":-").unwrap_or_else(|| {
                panic!("{value}: every compose variable has a default for local use")
            });
            variables.insert(name.to_string());
            out.push_str(default);
            rest = &inner[end + 1..];
        } else {
            panic!("{value}: write ${{NAME:-default}} (or $$ for a literal $)");
        }
    }
    out.push_str(rest);
    out
}

fn substitute_all(yaml: &Yaml, variables: &mut BTreeSet<String>) -> Yaml {
    match yaml {
        Yaml::String(value) => Yaml::String(substitute(value, variables)),
        Yaml::Array(items) => Yaml::Array(
            items
                .iter()
                .map(|item| substitute_all(item, variables))
                .collect(),
        ),
        Yaml::Hash(entries) => {
            let mut out = Hash::new();
            for (key, value) in entries {
                out.insert(key.clone(), substitute_all(value, variables));
            }
            Yaml::Hash(out)
        }
        other => other.clone(),
    }
}

/// compose.yaml with defaults substituted, and the variables it names.
fn compose() -> (Yaml, BTreeSet<String>) {
    let raw = single_document(&deploy("compose.yaml"));
    let mut variables = BTreeSet::new();
    let compose = substitute_all(&raw, &mut variables);
    (compose, variables)
}

fn compose_environment(service: &Yaml, name: &str) -> Vec<(String, String)> {
    match &service["environment"] {
        Yaml::Hash(entries) => entries
            .iter()
            .map(|(key, value)| {
                (
                    text(key, name),
                    scalar(value).unwrap_or_else(|| panic!("{name}: {key:?} has no value")),
                )
            })
            .collect(),
        Yaml::Array(items) => items
            .iter()
            .map(|item| {
                let item = text(item, name);
                let (key, value) = item.split_once('=').unwrap_or((&item, ""));
                (key.to_string(), value.to_string())
            })
            .collect(),
        Yaml::BadValue => Vec::new(),
        other => panic!("{name}: environment is {other:?}"),
    }
}

fn env_value(environment: &[(String, String)], name: &str) -> String {
    environment
        .iter()
        .find(|(key, _)| key == name)
        .map(|(_, value)| value.clone())
        .unwrap_or_else(|| panic!("{name} is not set"))
}

/// `host:port` of a URL such as `postgres://user:password@host:5432/db` or `http://host:9000`.
fn url_host_port(url: &str) -> (String, u16) {
    let after_scheme = url.split_once("://").map_or(url, |(_, rest)| rest);
    let authority = after_scheme.split('/').next().unwrap_or_default();
    let host_port = authority.rsplit('@').next().unwrap_or_default();
    let (host, port) = host_port
        .rsplit_once(':')
        .unwrap_or_else(|| panic!("{url}: no port"));
    (host.to_string(), port.parse().unwrap())
}

#[test]
fn compose_runs_the_services_commands_with_valid_settings() {
    let (compose, _) = compose();
    let services = &compose["services"];
    let mut images = BTreeSet::new();
    for (name, command) in [
        ("migrate", vec!["migrate"]),
        ("api", vec!["serve", "--api-only"]),
        ("worker", vec!["worker"]),
    ] {
        let service = &services[name];
        assert!(!service.is_badvalue(), "compose has a `{name}` service");
        images.insert(text(&service["image"], name));
        let build = &service["build"];
        let dockerfile = deploy("")
            .join(text(&build["context"], name))
            .join(text(&build["dockerfile"], name));
        assert!(
            dockerfile.is_file(),
            "{name} builds {}",
            dockerfile.display()
        );
        let args = strings(&service["command"], name);
        assert_eq!(args, command, "{name}");
        assert_command_exists(&args, &format!("compose {name}"));
        load_environment(
            &compose_environment(service, name),
            &format!("compose {name}"),
        );
    }
    assert_eq!(images.len(), 1, "one image for every segsplat service");
}

#[test]
fn compose_ports_healthchecks_and_gpu_match_the_settings() {
    let (compose, _) = compose();
    let services = &compose["services"];
    let api = load_environment(&compose_environment(&services["api"], "api"), "api");
    let worker = load_environment(
        &compose_environment(&services["worker"], "worker"),
        "worker",
    );
    assert!(api.http_addr.ip().is_unspecified() && api.grpc_addr.ip().is_unspecified());
    assert!(worker.workers.ops_addr.ip().is_unspecified());

    let published: BTreeSet<u16> = strings(&services["api"]["ports"], "api ports")
        .iter()
        .map(|mapping| mapping.rsplit(':').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(
        published,
        BTreeSet::from([api.http_addr.port(), api.grpc_addr.port()]),
        "the API publishes its REST and gRPC ports"
    );
    let exposed: Vec<String> = strings(&services["worker"]["expose"], "worker expose");
    assert_eq!(exposed, vec![worker.workers.ops_addr.port().to_string()]);

    for (name, port) in [
        ("api", api.http_addr.port()),
        ("worker", worker.workers.ops_addr.port()),
    ] {
        let test = strings(&services[name]["healthcheck"]["test"], name).join(" ");
        assert!(
            test.contains(&format!("/dev/tcp/127.0.0.1/{port} ")),
            "{name} checks its own port: {test}"
        );
        assert!(
            test.contains("GET /readyz ") || test.contains("GET /healthz "),
            "{test}"
        );
    }
    let postgres = strings(&services["postgres"]["healthcheck"]["test"], "postgres");
    assert!(
        postgres.iter().any(|word| word == "pg_isready"),
        "{postgres:?}"
    );

    // The worker's GPUs: NVIDIA devices through compose's device reservations.
    let devices = list(
        &services["worker"]["deploy"]["resources"]["reservations"]["devices"],
        "worker devices",
    );
    assert_eq!(devices.len(), 1);
    assert_eq!(devices[0]["driver"].as_str(), Some("nvidia"));
    assert!(strings(&devices[0]["capabilities"], "capabilities").contains(&"gpu".to_string()));
    // A worker must be given time to hand its job back (it waits up to jobs.lease_secs).
    let grace: f64 = text(&services["worker"]["stop_grace_period"], "grace")
        .trim_end_matches('s')
        .parse()
        .unwrap();
    assert!(grace > worker.jobs.lease_secs, "stop_grace_period {grace}");
}

#[test]
fn compose_services_start_in_order_and_reach_each_other() {
    let (compose, _) = compose();
    let services = compose["services"].as_hash().unwrap();
    let names: BTreeSet<String> = services.keys().map(|key| text(key, "service")).collect();
    let condition = |service: &str, on: &str| {
        compose["services"][service]["depends_on"][on]["condition"]
            .as_str()
            .map(str::to_string)
    };
    for (service, dependency) in services {
        let service = text(service, "service");
        if let Some(dependencies) = dependency["depends_on"].as_hash() {
            for (on, _) in dependencies {
                assert!(
                    names.contains(&text(on, &service)),
                    "{service} depends on {on:?}"
                );
            }
        }
    }
    assert_eq!(
        condition("migrate", "postgres").as_deref(),
        Some("service_healthy")
    );
    for service in ["api", "worker"] {
        for one_shot in ["migrate", "createbucket"] {
            assert_eq!(
                condition(service, one_shot).as_deref(),
                Some("service_completed_successfully"),
                "{service} starts after {one_shot} has finished"
            );
        }
    }

    // What the segsplat processes are told to reach is what the other services are.
    let environment = compose_environment(&compose["services"]["api"], "api");
    let database_url = env_value(&environment, "SEGSPLAT_DATABASE__URL");
    assert_eq!(url_host_port(&database_url), ("postgres".to_string(), 5432));
    let postgres = compose_environment(&compose["services"]["postgres"], "postgres");
    let credentials = format!(
        "://{}:{}@",
        env_value(&postgres, "POSTGRES_USER"),
        env_value(&postgres, "POSTGRES_PASSWORD")
    );
    assert!(database_url.contains(&credentials), "{database_url}");
    assert!(database_url.ends_with(&format!("/{}", env_value(&postgres, "POSTGRES_DB"))));

    let endpoint = env_value(&environment, "SEGSPLAT_BLOBS__ENDPOINT");
    let (store_host, _) = url_host_port(&endpoint);
    assert!(names.contains(&store_host), "{endpoint}");
    let minio = compose_environment(&compose["services"][store_host.as_str()], "minio");
    assert_eq!(
        env_value(&environment, "AWS_ACCESS_KEY_ID"),
        env_value(&minio, "MINIO_ROOT_USER")
    );
    assert_eq!(
        env_value(&environment, "AWS_SECRET_ACCESS_KEY"),
        env_value(&minio, "MINIO_ROOT_PASSWORD")
    );
    let bucket = env_value(&environment, "SEGSPLAT_BLOBS__URL")
        .strip_prefix("s3://")
        .and_then(|rest| rest.split('/').next().map(str::to_string))
        .unwrap();
    let create = strings(
        &compose["services"]["createbucket"]["command"],
        "createbucket",
    )
    .join(" ");
    assert!(
        create.contains(&format!("mc mb --ignore-existing local/{bucket}")),
        "{create}"
    );
    assert!(
        create.contains(&endpoint),
        "createbucket talks to {endpoint}: {create}"
    );
}

#[test]
fn compose_prometheus_and_grafana_are_wired_to_the_services() {
    let (compose, _) = compose();
    let services = &compose["services"];
    // Every folder or file compose mounts from this repository exists.
    let mut mounts = BTreeMap::new();
    for (name, service) in services.as_hash().unwrap() {
        let name = text(name, "service");
        if let Some(volumes) = service["volumes"].as_vec() {
            for volume in volumes {
                let volume = text(volume, &name);
                let mut parts = volume.split(':');
                let (source, target) = (parts.next().unwrap(), parts.next().unwrap());
                if source.starts_with('.') {
                    assert!(deploy(source).exists(), "{name} mounts {source}");
                    mounts.insert(source.to_string(), target.to_string());
                } else {
                    let named = &compose["volumes"][source];
                    assert!(!named.is_badvalue(), "{name}: volume {source} is declared");
                }
            }
        }
    }

    // Prometheus loads deploy/prometheus, whose static targets are compose services at the
    // ports their settings listen on.
    assert_eq!(mounts["./prometheus"], "/etc/prometheus");
    let command = strings(&services["prometheus"]["command"], "prometheus");
    assert!(command.contains(&"--config.file=/etc/prometheus/prometheus.yml".to_string()));
    let scrape = single_document(&deploy("prometheus/prometheus.yml"));
    let mut scraped = BTreeSet::new();
    for job in list(&scrape["scrape_configs"], "scrape_configs") {
        for target in strings(&job["static_configs"][0]["targets"], "targets") {
            let (host, port) = target.rsplit_once(':').unwrap();
            let settings = load_environment(&compose_environment(&services[host], host), "scraped");
            let expected = match host {
                "api" => settings.http_addr.port(),
                "worker" => settings.workers.ops_addr.port(),
                other => panic!("Prometheus scrapes {other}, no segsplat service"),
            };
            assert_eq!(port, expected.to_string(), "{target}");
            scraped.insert(host.to_string());
        }
    }
    assert_eq!(
        scraped,
        BTreeSet::from(["api".to_string(), "worker".to_string()])
    );

    // Grafana: the data source is the prometheus service; the dashboard provider reads the
    // folder the dashboards are mounted at.
    assert_eq!(
        mounts["./grafana/provisioning"],
        "/etc/grafana/provisioning"
    );
    let datasources = single_document(&deploy("grafana/provisioning/datasources/prometheus.yml"));
    let datasource = &list(&datasources["datasources"], "datasources")[0];
    assert_eq!(datasource["type"].as_str(), Some("prometheus"));
    let (host, port) = url_host_port(&text(&datasource["url"], "url"));
    assert_eq!(host, "prometheus");
    assert!(
        strings(&services["prometheus"]["ports"], "ports")
            .iter()
            .any(|mapping| mapping.ends_with(&format!(":{port}"))),
        "Prometheus listens on {port}"
    );
    let providers = single_document(&deploy("grafana/provisioning/dashboards/segsplat.yml"));
    let provider = &list(&providers["providers"], "providers")[0];
    assert_eq!(
        provider["options"]["path"].as_str(),
        Some(mounts["./grafana/dashboards"].as_str())
    );
    assert!(deploy("grafana/dashboards/segsplat.json").is_file());
}

#[test]
fn compose_variables_are_in_the_example_env_file() {
    let (_, variables) = compose();
    let example: BTreeSet<String> = env_file(&deploy(".env.example"))
        .into_iter()
        .map(|(name, _)| name)
        .collect();
    assert_eq!(
        variables, example,
        "deploy/.env.example lists every variable"
    );
    let ignored = read(&repo().join(".gitignore"));
    assert!(
        ignored.lines().any(|line| line.trim() == "deploy/.env"),
        "the filled-in copy stays out of git"
    );
}
