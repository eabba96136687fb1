//! Paths named inside dataset files (image names, `file_path`) are untrusted: they must stay
//! inside the dataset folder.

use std::path::{Component, Path, PathBuf};

/// `path` as plain relative components (`.` dropped), or `None` when it is empty, absolute or
/// climbs with `..`. A backslash separates components too: transforms.json files written on
/// Windows (instant-ngp's own samples) name `images\0001.jpg`, and no dataset names a file
/// with a backslash in it.
pub fn contained_relative_path(path: &str) -> Option<PathBuf> {
    let path = path.replace('\\', "/");
    let mut relative = PathBuf::new();
    for component in Path::new(&path).components() {
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
        assert_eq!(
            contained_relative_path("images\\0001.jpg"),
            Some(PathBuf::from("images/0001.jpg"))
        );
        assert_eq!(
            contained_relative_path(".\\images\\sub/0001.jpg"),
            Some(PathBuf::from("images/sub/0001.jpg"))
        );
        for escaping in [
            "",
            ".",
            "/etc/passwd",
            "../a.png",
            "images/../../a.png",
            "..\\..\\etc\\passwd",
            "\\etc\\passwd",
        ] {
            assert_eq!(contained_relative_path(escaping), None, "{escaping:?}");
        }
    }
}
