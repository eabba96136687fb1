//! Paths named inside dataset files (image names, `file_path`) are untrusted: they must stay
//! inside the dataset folder.

use std::path::{Component, Path, PathBuf};

/// `path` as plain relative components (`.` dropped), or `None` when it is empty, absolute or
/// climbs with `..`.
pub fn contained_relative_path(path: &str) -> Option<PathBuf> {
    let mut relative = PathBuf::new();
    for component in Path::new(path).components() {
        match component {
            Component::Normal(part) => relative.push(part),
            Component::CurDir => {}
            Component::ParentDir | Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    (!relative.as_os_str().is_empty()).then_some(relative)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_paths_inside_the_dataset_pass() {
        assert_eq!(
            contained_relative_path("./images/a.png"),
            Some(PathBuf::from("images/a.png"))
        );
        for escaping in ["", ".", "/etc/passwd", "../a.png", "images/../../a.png"] {
            assert_eq!(contained_relative_path(escaping), None, "{escaping:?}");
        }
    }
}
