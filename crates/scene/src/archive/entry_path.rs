//! Turning an archive entry name into a path that cannot leave the unpack directory.

use std::path::PathBuf;

use super::ArchiveError;

/// Folders an entry may be nested in. Datasets need a handful (`masks/small/train/r_0.png`);
/// thousands would only exhaust the file system's path length, a server error otherwise.
pub const MAX_ENTRY_DEPTH: usize = 32;
/// Longest name of one path component (the common file-system limit).
pub const MAX_COMPONENT_BYTES: usize = 255;
/// Longest whole entry name.
pub const MAX_ENTRY_BYTES: usize = 1024;

/// The entry name as a relative path of plain components, or `UnsafePath`.
///
/// Rejected: absolute names (`/x`), any `..` component, backslashes (a Windows separator that
/// would be a plain character here, or a trick to smuggle `..\`), `:` (drive prefixes like `C:`
/// and alternate data streams), and NUL bytes. Empty and `.` components are dropped, so `./a//b`
/// is `a/b`. Returns `Ok(None)` for names that reduce to the root (`./`). Names deeper than
/// [`MAX_ENTRY_DEPTH`] folders or longer than [`MAX_ENTRY_BYTES`] (a component longer than
/// [`MAX_COMPONENT_BYTES`]) are `PathTooLong`.
pub fn safe_relative_path(entry: &str) -> Result<Option<PathBuf>, ArchiveError> {
    let unsafe_path = || ArchiveError::UnsafePath {
        entry: entry.to_string(),
    };
    if entry.starts_with('/') || entry.contains(['\\', ':', '\0']) {
        return Err(unsafe_path());
    }
    let too_long = |problem: String| ArchiveError::PathTooLong {
        entry: shortened(entry),
        problem,
    };
    let mut path = PathBuf::new();
    let mut depth = 0usize;
    for component in entry.split('/') {
        match component {
            "" | "." => {}
            ".." => return Err(unsafe_path()),
            plain if plain.len() > MAX_COMPONENT_BYTES => {
                return Err(too_long(format!(
                    "a name in it is {} bytes long, at most {MAX_COMPONENT_BYTES} are allowed",
                    plain.len()
                )));
            }
            plain => {
                depth += 1;
                path.push(plain);
            }
        }
    }
    // The last component is the entry itself; the rest are folders.
    if depth > MAX_ENTRY_DEPTH + 1 {
        return Err(too_long(format!(
            "nested {} folders deep, at most {MAX_ENTRY_DEPTH} are allowed",
            depth - 1
        )));
    }
    if entry.len() > MAX_ENTRY_BYTES {
        return Err(too_long(format!(
            "name is {} bytes long, at most {MAX_ENTRY_BYTES} are allowed",
            entry.len()
        )));
    }
    Ok(if path.as_os_str().is_empty() {
        None
    } else {
        Some(path)
    })
}

/// The start of a long entry name, enough to recognise it in a message.
fn shortened(entry: &str) -> String {
    const SHOWN: usize = 120;
    if entry.len() <= SHOWN {
        return entry.to_string();
    }
    let mut end = SHOWN;
    while !entry.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}...", &entry[..end])
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
    fn deep_and_long_names_are_rejected() {
        let at_limit = format!("{}f.png", "d/".repeat(MAX_ENTRY_DEPTH));
        assert!(safe_relative_path(&at_limit).unwrap().is_some());
        let too_deep = format!("{}f.png", "d/".repeat(MAX_ENTRY_DEPTH + 1));
        let error = safe_relative_path(&too_deep).unwrap_err();
        assert!(matches!(error, ArchiveError::PathTooLong { .. }), "{error}");
        assert!(error.to_string().contains("at most 32"), "{error}");
        let long_name = "x".repeat(MAX_COMPONENT_BYTES + 1);
        assert!(matches!(
            safe_relative_path(&long_name),
            Err(ArchiveError::PathTooLong { .. })
        ));
        let huge = format!("{}f", "ab/".repeat(3000));
        let error = safe_relative_path(&huge).unwrap_err().to_string();
        assert!(error.len() < 300, "{error}");
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
