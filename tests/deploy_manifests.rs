//! What can be checked of `deploy/compose.yaml` and `deploy/kubernetes/` without docker or a
//! cluster (neither exists on these machines): every file parses; kustomizations name files that
//! exist; every `SEGSPLAT_*` variable is a configuration key and the settings load; ports,
//! probes and scrape targets are the ones the settings make the service listen on; the
//! commands and flags exist in the built binary; and the objects refer to each other correctly
//! (HPA target, PDB and Service selectors, generated ConfigMap and Secret names, GPU request).
//! Where `kubectl` is installed, the overlay is also rendered by kustomize, and where
//! `kubernetes-validate` is, the rendered objects are checked against the Kubernetes schemas.

#[path = "common/segsplat_bin.rs"]
mod segsplat_bin;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use segsplat_service::config::{Config, ConfigOverrides};
use yaml_rust2::yaml::Hash;
use yaml_rust2::{Yaml, YamlLoader};

// ---------------------------------------------------------------------------------------------
// Reading files

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn deploy(relative: &str) -> PathBuf {
    repo().join("deploy").join(relative)
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|error| panic!("{}: {error}", path.display()))
}

/// Every document of a (multi-document) YAML file.
fn documents(path: &Path) -> Vec<Yaml> {
    YamlLoader::load_from_str(&read(path))
        .unwrap_or_else(|error| panic!("{} is not YAML: {error}", path.display()))
        .into_iter()
        .filter(|document| !document.is_null())
        .collect()
}

fn single_document(path: &Path) -> Yaml {
    let mut documents = documents(path);
    assert_eq!(documents.len(), 1, "{}", path.display());
    documents.remove(0)
}

fn yaml_files(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(dir) = pending.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                pending.push(path);
            } else if matches!(
                path.extension().and_then(|e| e.to_str()),
                Some("yaml" | "yml")
            ) {
                found.push(path);
            }
        }
    }
    found.sort();
    found
}

/// A scalar as the string a container would see (`8080`, `true` and `"8080"` alike).
fn scalar(yaml: &Yaml) -> Option<String> {
    match yaml {
        Yaml::String(text) | Yaml::Real(text) => Some(text.clone()),
        Yaml::Integer(number) => Some(number.to_string()),
        Yaml::Boolean(flag) => Some(flag.to_string()),
        _ => None,
    }
}

fn text(yaml: &Yaml, what: &str) -> String {
    scalar(yaml).unwrap_or_else(|| panic!("{what}: expected a scalar, found {yaml:?}"))
}

fn list<'a>(yaml: &'a Yaml, what: &str) -> &'a Vec<Yaml> {
    yaml.as_vec()
        .unwrap_or_else(|| panic!("{what}: expected a list, found {yaml:?}"))
}

fn strings(yaml: &Yaml, what: &str) -> Vec<String> {
    list(yaml, what)
        .iter()
        .map(|item| text(item, what))
        .collect()
}

/// `KEY=VALUE` lines of a kustomize env file (comments and blank lines skipped).
fn env_file(path: &Path) -> Vec<(String, String)> {
    read(path)
        .lines()
        .map(str::trim)
        .filter(|line| !line.is_empty() && !line.starts_with('#'))
        .map(|line| {
            let (name, value) = line
                .split_once('=')
                .unwrap_or_else(|| panic!("{}: not KEY=VALUE: {line}", path.display()));
            (name.to_string(), value.to_string())
        })
        .collect()
}

/// The image's user id (`useradd ... --uid N`), which pods must run as.
fn image_uid() -> i64 {
    let dockerfile = read(&deploy("docker/Dockerfile"));
    let after = dockerfile
        .split("--uid ")
        .nth(1)
        .expect("the Dockerfile creates its user with --uid");
    after
        .split_whitespace()
        .next()
        .and_then(|uid| uid.parse().ok())
        .expect("a numeric uid")
}

// ---------------------------------------------------------------------------------------------
// Configuration

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
fn load_environment(environment: &[(String, String)], place: &str) -> Config {
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
fn assert_command_exists(args: &[String], place: &str) {
    let subcommand = args
        .first()
        .unwrap_or_else(|| panic!("{place}: no subcommand"));
    let output = Command::new(segsplat_bin::segsplat_bin())
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

// ---------------------------------------------------------------------------------------------
// Compose

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

// ---------------------------------------------------------------------------------------------
// Kubernetes

fn kubernetes(relative: &str) -> PathBuf {
    deploy("kubernetes").join(relative)
}

fn kustomization(dir: &Path) -> Yaml {
    single_document(&dir.join("kustomization.yaml"))
}

/// The objects of the base's resource files, in order.
fn base_objects() -> Vec<Yaml> {
    let base = kubernetes("base");
    strings(&kustomization(&base)["resources"], "resources")
        .iter()
        .flat_map(|resource| documents(&base.join(resource)))
        .collect()
}

fn object<'a>(objects: &'a [Yaml], kind: &str, name: &str) -> &'a Yaml {
    objects
        .iter()
        .find(|object| {
            object["kind"].as_str() == Some(kind)
                && object["metadata"]["name"].as_str() == Some(name)
        })
        .unwrap_or_else(|| panic!("no {kind} {name}"))
}

fn of_kind<'a>(objects: &'a [Yaml], kind: &'a str) -> impl Iterator<Item = &'a Yaml> + 'a {
    objects
        .iter()
        .filter(move |object| object["kind"].as_str() == Some(kind))
}

fn labels(yaml: &Yaml) -> BTreeMap<String, String> {
    yaml.as_hash()
        .map(|entries| {
            entries
                .iter()
                .map(|(key, value)| (text(key, "label"), text(value, "label")))
                .collect()
        })
        .unwrap_or_default()
}

fn selects(selector: &BTreeMap<String, String>, pod: &BTreeMap<String, String>) -> bool {
    !selector.is_empty()
        && selector
            .iter()
            .all(|(key, value)| pod.get(key) == Some(value))
}

/// Env files of the base's generators, by generated name (`configMapGenerator`,
/// `secretGenerator`).
fn generated(dir: &Path, field: &str) -> BTreeMap<String, Vec<(String, String)>> {
    let mut out = BTreeMap::new();
    if let Some(generators) = kustomization(dir)[field].as_vec() {
        for generator in generators {
            let name = text(&generator["name"], field);
            let mut pairs = Vec::new();
            if let Some(envs) = generator["envs"].as_vec() {
                for env in envs {
                    pairs.extend(env_file(&dir.join(text(env, field))));
                }
            }
            if let Some(literals) = generator["literals"].as_vec() {
                for literal in literals {
                    let literal = text(literal, field);
                    let (key, value) = literal.split_once('=').unwrap();
                    pairs.push((key.to_string(), value.to_string()));
                }
            }
            out.insert(name, pairs);
        }
    }
    out
}

/// A workload's pod spec (Deployment or Job).
fn pod_spec(workload: &Yaml) -> &Yaml {
    &workload["spec"]["template"]["spec"]
}

/// The one container of a workload, with the environment its `envFrom` and `env` give it,
/// `overlay` values (a `behavior: merge` generator) overriding the base's.
fn container_environment(
    container: &Yaml,
    overlay: &BTreeMap<String, Vec<(String, String)>>,
) -> Vec<(String, String)> {
    let base = kubernetes("base");
    let config_maps = generated(&base, "configMapGenerator");
    let secrets = generated(&base, "secretGenerator");
    let mut environment: BTreeMap<String, String> = BTreeMap::new();
    for source in list(&container["envFrom"], "envFrom") {
        let (pairs, name) = if let Some(name) = source["configMapRef"]["name"].as_str() {
            (config_maps.get(name), name)
        } else if let Some(name) = source["secretRef"]["name"].as_str() {
            (secrets.get(name), name)
        } else {
            panic!("envFrom {source:?}")
        };
        let pairs = pairs.unwrap_or_else(|| panic!("envFrom {name}: no generator of that name"));
        environment.extend(pairs.iter().cloned());
        if let Some(merged) = overlay.get(name) {
            environment.extend(merged.iter().cloned());
        }
    }
    if let Some(variables) = container["env"].as_vec() {
        for variable in variables {
            let name = text(&variable["name"], "env");
            // valueFrom (a field or a secret key) has no value here; the name is still checked.
            let value = scalar(&variable["value"]).unwrap_or_default();
            environment.insert(name, value);
        }
    }
    environment.into_iter().collect()
}

fn only_container(workload: &Yaml) -> &Yaml {
    let containers = list(&pod_spec(workload)["containers"], "containers");
    assert_eq!(containers.len(), 1, "{:?}", workload["metadata"]["name"]);
    &containers[0]
}

fn container_ports(container: &Yaml) -> BTreeMap<String, u16> {
    list(&container["ports"], "ports")
        .iter()
        .map(|port| {
            (
                text(&port["name"], "port name"),
                port["containerPort"].as_i64().unwrap() as u16,
            )
        })
        .collect()
}

/// The workloads by role: the Deployment running `serve --api-only`, the one running
/// `worker`, the Job running `migrate`.
fn workload<'a>(objects: &'a [Yaml], subcommand: &str) -> &'a Yaml {
    let mut found = objects.iter().filter(|object| {
        matches!(object["kind"].as_str(), Some("Deployment" | "Job"))
            && only_container(object)["args"][0].as_str() == Some(subcommand)
    });
    let workload = found
        .next()
        .unwrap_or_else(|| panic!("no workload runs `segsplat {subcommand}`"));
    assert!(found.next().is_none(), "one workload runs {subcommand}");
    workload
}

#[test]
fn every_deploy_yaml_file_parses_and_names_its_objects() {
    let mut files = yaml_files(&deploy("kubernetes"));
    assert!(files.len() >= 8, "{files:?}");
    files.extend(yaml_files(&deploy("grafana")));
    files.push(deploy("compose.yaml"));
    for file in files {
        for document in documents(&file) {
            assert!(document.as_hash().is_some(), "{}", file.display());
            if file.starts_with(deploy("kubernetes")) {
                assert!(
                    document["apiVersion"].as_str().is_some(),
                    "{}",
                    file.display()
                );
                let kind = document["kind"].as_str().unwrap_or_default();
                if kind != "Kustomization" {
                    assert!(
                        document["metadata"]["name"].as_str().is_some(),
                        "{}",
                        file.display()
                    );
                }
            }
        }
    }
}

#[test]
fn kustomizations_name_files_that_exist_and_leave_none_out() {
    let base_objects = base_objects();
    for file in yaml_files(&deploy("kubernetes")) {
        if file.file_name().and_then(|name| name.to_str()) != Some("kustomization.yaml") {
            continue;
        }
        let dir = file.parent().unwrap();
        let kustomization = kustomization(dir);
        assert_eq!(kustomization["kind"].as_str(), Some("Kustomization"));
        let mut used = BTreeSet::new();
        for resource in strings(&kustomization["resources"], "resources") {
            let path = dir.join(&resource);
            assert!(
                path.is_file() || path.join("kustomization.yaml").is_file(),
                "{}: resource {resource} does not exist",
                file.display()
            );
            used.insert(resource);
        }
        if let Some(patches) = kustomization["patches"].as_vec() {
            for patch in patches {
                let path = text(&patch["path"], "patch");
                let patch_file = dir.join(&path);
                assert!(patch_file.is_file(), "{}: patch {path}", file.display());
                // A strategic-merge patch names the base object it changes.
                for document in documents(&patch_file) {
                    object(
                        &base_objects,
                        &text(&document["kind"], "kind"),
                        &text(&document["metadata"]["name"], "name"),
                    );
                }
                used.insert(path);
            }
        }
        for field in ["configMapGenerator", "secretGenerator"] {
            for generator in kustomization[field].as_vec().into_iter().flatten() {
                for env in generator["envs"].as_vec().into_iter().flatten() {
                    let env = text(env, field);
                    assert!(dir.join(&env).is_file(), "{}: {env}", file.display());
                    used.insert(env);
                }
            }
        }
        // A manifest beside a kustomization that it does not name would be silently skipped.
        for entry in std::fs::read_dir(dir).unwrap() {
            let name = entry.unwrap().file_name().into_string().unwrap();
            if name != "kustomization.yaml" && (name.ends_with(".yaml") || name.ends_with(".env")) {
                assert!(
                    used.contains(&name),
                    "{}: {name} is not used",
                    file.display()
                );
            }
        }
    }
}

#[test]
fn the_example_overlay_builds_on_the_base() {
    let overlay_dir = kubernetes("overlays/example");
    let overlay = kustomization(&overlay_dir);
    let resources = strings(&overlay["resources"], "resources");
    assert!(
        resources.contains(&"../../base".to_string()),
        "{resources:?}"
    );
    let namespace = text(&overlay["namespace"], "namespace");
    let namespace_object = single_document(&overlay_dir.join("namespace.yaml"));
    assert_eq!(namespace_object["kind"].as_str(), Some("Namespace"));
    assert_eq!(
        namespace_object["metadata"]["name"].as_str(),
        Some(namespace.as_str())
    );
    let image = &list(&overlay["images"], "images")[0];
    assert_eq!(
        image["name"].as_str(),
        Some("segsplat"),
        "the base's image name"
    );
    assert!(scalar(&image["newTag"]).is_some(), "a pinned tag");

    let base_objects = base_objects();
    for replicas in list(&overlay["replicas"], "replicas") {
        object(
            &base_objects,
            "Deployment",
            &text(&replicas["name"], "replicas"),
        );
    }
    // Merged settings are configuration keys too and load with the base's.
    let merged = generated(&overlay_dir, "configMapGenerator");
    let base_config_maps = generated(&kubernetes("base"), "configMapGenerator");
    for name in merged.keys() {
        assert!(base_config_maps.contains_key(name), "merges into {name}");
    }
    for subcommand in ["serve", "worker", "migrate"] {
        let container = only_container(workload(&base_objects, subcommand));
        load_environment(
            &container_environment(container, &merged),
            &format!("overlay {subcommand}"),
        );
    }
}

#[test]
fn kubernetes_workloads_run_the_services_commands_with_valid_settings() {
    let objects = base_objects();
    let uid = image_uid();
    let secrets = generated(&kubernetes("base"), "secretGenerator");
    for values in secrets.values() {
        for (name, value) in values {
            assert!(
                value.contains("REPLACE_ME"),
                "{name} is an obvious placeholder"
            );
        }
    }
    for (subcommand, args) in [
        ("serve", vec!["serve", "--api-only"]),
        ("worker", vec!["worker"]),
        ("migrate", vec!["migrate"]),
    ] {
        let workload = workload(&objects, subcommand);
        let name = text(&workload["metadata"]["name"], "name");
        let container = only_container(workload);
        assert!(
            container["command"].is_badvalue(),
            "{name}: the image's entrypoint is segsplat"
        );
        assert_eq!(container["image"].as_str(), Some("segsplat"), "{name}");
        let given = strings(&container["args"], &name);
        assert_eq!(given, args, "{name}");
        assert_command_exists(&given, &name);
        let config = load_environment(&container_environment(container, &BTreeMap::new()), &name);
        assert!(config.database.url.is_some(), "{name}: shared PostgreSQL");
        assert!(config.blobs.url.is_some(), "{name}: shared bucket");

        let pod = pod_spec(workload);
        assert_eq!(pod["securityContext"]["runAsNonRoot"].as_bool(), Some(true));
        assert_eq!(pod["securityContext"]["runAsUser"].as_i64(), Some(uid));
        assert_eq!(pod["enableServiceLinks"].as_bool(), Some(false), "{name}");
        let security = &container["securityContext"];
        assert_eq!(security["allowPrivilegeEscalation"].as_bool(), Some(false));
        assert_eq!(security["readOnlyRootFilesystem"].as_bool(), Some(true));
        // With a read-only root, the data dir and /tmp (XDG_RUNTIME_DIR) are volumes.
        let mounted: BTreeSet<String> = list(&container["volumeMounts"], "volumeMounts")
            .iter()
            .map(|mount| text(&mount["mountPath"], "mountPath"))
            .collect();
        assert!(
            mounted.contains(config.data_dir.to_str().unwrap()),
            "{name}"
        );
        assert!(mounted.contains("/tmp"), "{name}");
        let resources = &container["resources"];
        assert!(resources["requests"]["memory"].as_str().is_some(), "{name}");
        assert!(resources["limits"]["memory"].as_str().is_some(), "{name}");
    }
    let job = workload(&objects, "migrate");
    assert_eq!(job["kind"].as_str(), Some("Job"));
    assert!(matches!(
        pod_spec(job)["restartPolicy"].as_str(),
        Some("Never" | "OnFailure")
    ));
}

#[test]
fn kubernetes_ports_probes_and_scraping_match_the_settings() {
    let objects = base_objects();
    for (subcommand, kind) in [("serve", "api"), ("worker", "worker")] {
        let workload = workload(&objects, subcommand);
        let name = text(&workload["metadata"]["name"], "name");
        let container = only_container(workload);
        let config = load_environment(&container_environment(container, &BTreeMap::new()), &name);
        let ports = container_ports(container);
        let metrics_port = if kind == "api" {
            assert_eq!(
                ports,
                BTreeMap::from([
                    ("http".to_string(), config.http_addr.port()),
                    ("grpc".to_string(), config.grpc_addr.port()),
                ]),
                "{name}"
            );
            assert!(
                config.http_addr.ip().is_unspecified() && config.grpc_addr.ip().is_unspecified()
            );
            config.http_addr.port()
        } else {
            assert_eq!(
                ports,
                BTreeMap::from([("ops".to_string(), config.workers.ops_addr.port())]),
                "{name}"
            );
            assert!(config.workers.ops_addr.ip().is_unspecified());
            config.workers.ops_addr.port()
        };
        for (probe, path) in [
            ("startupProbe", "/healthz"),
            ("livenessProbe", "/healthz"),
            ("readinessProbe", "/readyz"),
        ] {
            let get = &container[probe]["httpGet"];
            assert_eq!(get["path"].as_str(), Some(path), "{name} {probe}");
            let port = match &get["port"] {
                Yaml::String(port_name) => ports[port_name.as_str()],
                Yaml::Integer(number) => *number as u16,
                other => panic!("{name} {probe} port {other:?}"),
            };
            assert_eq!(
                port, metrics_port,
                "{name} {probe} asks the port serving the probes"
            );
        }
        // A process listens only after the database answered, which it retries for
        // database.connect_retry_secs: the startup probe must wait longer.
        let startup = &container["startupProbe"];
        let budget = startup["periodSeconds"].as_i64().unwrap()
            * startup["failureThreshold"].as_i64().unwrap();
        assert!(
            budget as u64 > config.database.connect_retry_secs,
            "{name}: startup budget {budget} s"
        );

        let annotations = labels(&workload["spec"]["template"]["metadata"]["annotations"]);
        assert_eq!(annotations["prometheus.io/scrape"], "true", "{name}");
        assert_eq!(annotations["prometheus.io/port"], metrics_port.to_string());
        assert_eq!(annotations["prometheus.io/path"], "/metrics");

        // The kubernetes_sd scrape jobs keep exactly these pods at this port's name.
        let scrape_map = object(&objects, "ConfigMap", "segsplat-prometheus-scrape");
        let scrape =
            YamlLoader::load_from_str(&text(&scrape_map["data"]["segsplat-scrape.yml"], "scrape"))
                .unwrap()
                .remove(0);
        let job_name = format!("segsplat-{kind}");
        let job = list(&scrape["scrape_configs"], "scrape_configs")
            .iter()
            .find(|job| job["job_name"].as_str() == Some(job_name.as_str()))
            .unwrap_or_else(|| panic!("no scrape job {job_name}"));
        assert_eq!(job["metrics_path"].as_str(), Some("/metrics"));
        assert_eq!(
            job["kubernetes_sd_configs"][0]["role"].as_str(),
            Some("pod")
        );
        let keep = &list(&job["relabel_configs"], "relabel_configs")[0];
        assert_eq!(keep["action"].as_str(), Some("keep"));
        let pod_labels = labels(&workload["spec"]["template"]["metadata"]["labels"]);
        let port_name = ports
            .iter()
            .find(|(_, port)| **port == metrics_port)
            .map(|(port_name, _)| port_name.clone())
            .unwrap();
        let expected = format!(
            "{};{};{port_name}",
            pod_labels["app.kubernetes.io/name"], pod_labels["app.kubernetes.io/component"]
        );
        assert_eq!(
            keep["regex"].as_str(),
            Some(expected.as_str()),
            "{job_name}"
        );
    }
    // The job names are those of the single-host scrape file, which the dashboard was built on.
    let single_host = single_document(&deploy("prometheus/prometheus.yml"));
    let names: BTreeSet<String> = list(&single_host["scrape_configs"], "scrape_configs")
        .iter()
        .map(|job| text(&job["job_name"], "job_name"))
        .collect();
    assert_eq!(
        names,
        BTreeSet::from(["segsplat-api".to_string(), "segsplat-worker".to_string()])
    );
}

#[test]
fn kubernetes_objects_refer_to_each_other() {
    let objects = base_objects();
    let api = workload(&objects, "serve");
    let worker = workload(&objects, "worker");
    let api_name = text(&api["metadata"]["name"], "name");
    let api_pods = labels(&api["spec"]["template"]["metadata"]["labels"]);
    let worker_pods = labels(&worker["spec"]["template"]["metadata"]["labels"]);
    for deployment in of_kind(&objects, "Deployment") {
        let selector = labels(&deployment["spec"]["selector"]["matchLabels"]);
        let pods = labels(&deployment["spec"]["template"]["metadata"]["labels"]);
        assert!(
            selects(&selector, &pods),
            "{:?}",
            deployment["metadata"]["name"]
        );
    }
    assert!(
        api["spec"]["replicas"].is_badvalue(),
        "the autoscaler owns the API's replica count"
    );

    let hpa = of_kind(&objects, "HorizontalPodAutoscaler")
        .next()
        .expect("an autoscaler");
    assert_eq!(hpa["apiVersion"].as_str(), Some("autoscaling/v2"));
    assert_eq!(
        hpa["spec"]["scaleTargetRef"]["kind"].as_str(),
        Some("Deployment")
    );
    assert_eq!(
        hpa["spec"]["scaleTargetRef"]["name"].as_str(),
        Some(api_name.as_str())
    );
    assert_eq!(
        hpa["spec"]["metrics"][0]["resource"]["name"].as_str(),
        Some("cpu")
    );
    // Utilization targets need CPU requests to divide by.
    assert!(scalar(&only_container(api)["resources"]["requests"]["cpu"]).is_some());

    let pdb = of_kind(&objects, "PodDisruptionBudget")
        .next()
        .expect("a disruption budget");
    let pdb_selector = labels(&pdb["spec"]["selector"]["matchLabels"]);
    assert!(selects(&pdb_selector, &api_pods));
    assert!(!selects(&pdb_selector, &worker_pods));

    let service = object(&objects, "Service", &api_name);
    let service_selector = labels(&service["spec"]["selector"]);
    assert!(
        selects(&service_selector, &api_pods),
        "{service_selector:?}"
    );
    assert!(
        !selects(&service_selector, &worker_pods),
        "workers serve no API"
    );
    let api_ports = container_ports(only_container(api));
    for port in list(&service["spec"]["ports"], "ports") {
        let target = text(&port["targetPort"], "targetPort");
        let container_port = api_ports
            .get(&target)
            .unwrap_or_else(|| panic!("the Service targets {target}, no API port"));
        assert_eq!(port["port"].as_i64(), Some(i64::from(*container_port)));
    }

    // The worker holds one GPU; a stopping worker gets to hand its job back.
    let worker_container = only_container(worker);
    assert_eq!(
        worker_container["resources"]["limits"]["nvidia.com/gpu"].as_i64(),
        Some(1)
    );
    let config = load_environment(
        &container_environment(worker_container, &BTreeMap::new()),
        "worker",
    );
    let grace = pod_spec(worker)["terminationGracePeriodSeconds"]
        .as_i64()
        .unwrap();
    assert!(
        grace as f64 >= config.jobs.lease_secs + 30.0,
        "terminationGracePeriodSeconds {grace} vs jobs.lease_secs {}",
        config.jobs.lease_secs
    );
    assert_eq!(
        worker["spec"]["strategy"]["rollingUpdate"]["maxSurge"].as_i64(),
        Some(0),
        "a rollout needs no spare GPU"
    );
}

// ---------------------------------------------------------------------------------------------
// Real tools, where installed

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
