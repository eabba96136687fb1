//! Kubernetes

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use yaml_rust2::{Yaml, YamlLoader};

use crate::files::{
    deploy, documents, env_file, image_uid, list, scalar, single_document, strings, text,
    yaml_files,
};
use crate::settings::{assert_command_exists, load_environment};

pub(crate) fn kubernetes(relative: &str) -> PathBuf {
    deploy("kubernetes").join(relative)
}

pub(crate) fn kustomization(dir: &Path) -> Yaml {
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

pub(crate) fn only_container(workload: &Yaml) -> &Yaml {
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
pub(crate) fn workload<'a>(objects: &'a [Yaml], subcommand: &str) -> &'a Yaml {
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
