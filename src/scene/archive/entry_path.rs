//! Turning an archive entry name into a path that cannot leave the unpack directory.

use std::path::PathBuf;

use super::ArchiveError;

/// The entry name as a relative path of plain components, or `UnsafePath`.
///
/// Rejected: absolute names (`/x`), any `..` component, backslashes (a Windows separator that
/// would be a plain character here, or a trick to smuggle `..\`), `:` (drive prefixes like `C:`
/// and alternate data streams), and NUL bytes. Empty and `.` components are dropped, so `./a//b`
/// is `a/b`. Returns `Ok(None)` for names that reduce to the root (`./`).
pub fn safe_relative_path(entry: &str) -> Result<Option<PathBuf>, ArchiveError> {
    let unsafe_path = || ArchiveError::UnsafePath {
        entry: entry.to_string(),
    };
    if entry.starts_with('/') || entry.contains(['\\', ':', '\0']) {
        return Err(unsafe_path());
    }
    let mut path = PathBuf::new();
    for component in entry.split('/') {
        match component {
            "" | "." => {}
            ".." => return Err(unsafe_path()),
            plain => path.push(plain),
        }
    }
    Ok(if path.as_os_str().is_empty() {
        None
    } else {
        Some(path)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_names_are_kept_and_dots_dropped() {
        let path = safe_relative_path("./scene//images/./a.png").unwrap();
        assert_eq!(path, Some(PathBuf::from("scene/images/a.png")));
        assert_eq!(safe_relative_path("./").unwrap(), None);
    }

    #[test]
    fn escaping_names_are_rejected() {
        for name in [
            "/etc/passwd",
            "../x",
            "a/../../x",
            "a/..",
            "..\\x",
            "a\\b",
            "C:/x",
            "C:x",
            "a\0b",
        ] {
            assert!(
                matches!(
                    safe_relative_path(name),
                    Err(ArchiveError::UnsafePath { .. })
                ),
                "{name:?} should be rejected"
            );
        }
    }
}
