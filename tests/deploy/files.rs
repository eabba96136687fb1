//! Reading files

use std::path::{Path, PathBuf};

use yaml_rust2::{Yaml, YamlLoader};

pub(crate) fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

pub(crate) fn deploy(relative: &str) -> PathBuf {
    repo().join("deploy").join(relative)
}

pub(crate) fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|error| panic!("{}: {error}", path.display()))
}

/// Every document of a (multi-document) YAML file.
pub(crate) fn documents(path: &Path) -> Vec<Yaml> {
    YamlLoader::load_from_str(&read(path))
        .unwrap_or_else(|error| panic!("{} is not YAML: {error}", path.display()))
        .into_iter()
        .filter(|document| !document.is_null())
        .collect()
}

pub(crate) fn single_document(path: &Path) -> Yaml {
    let mut documents = documents(path);
    assert_eq!(documents.len(), 1, "{}", path.display());
    documents.remove(0)
}

pub(crate) fn yaml_files(dir: &Path) -> Vec<PathBuf> {
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
pub(crate) fn scalar(yaml: &Yaml) -> Option<String> {
    match yaml {
        Yaml::String(text) | Yaml::Real(text) => Some(text.clone()),
        Yaml::Integer(number) => Some(number.to_string()),
        Yaml::Boolean(flag) => Some(flag.to_string()),
        _ => None,
    }
}

pub(crate) fn text(yaml: &Yaml, what: &str) -> String {
    scalar(yaml).unwrap_or_else(|| panic!("{what}: expected a scalar, found {yaml:?}"))
}

pub(crate) fn list<'a>(yaml: &'a Yaml, what: &str) -> &'a Vec<Yaml> {
    yaml.as_vec()
        .unwrap_or_else(|| panic!("{what}: expected a list, found {yaml:?}"))
}

pub(crate) fn strings(yaml: &Yaml, what: &str) -> Vec<String> {
    list(yaml, what)
        .iter()
        .map(|item| text(item, what))
        .collect()
}

/// `KEY=VALUE` lines of a kustomize env file (comments and blank lines skipped).
pub(crate) fn env_file(path: &Path) -> Vec<(String, String)> {
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
pub(crate) fn image_uid() -> i64 {
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
