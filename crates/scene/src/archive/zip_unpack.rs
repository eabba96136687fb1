//! Zip entries through the `zip` crate, after [`check_directory`] has checked the central
//! directory's names, entry count and declared sizes; links and special files are told apart by
//! the unix mode bits stored in the central directory. An entry that inflates past its declared
//! size is refused by the crate ("larger than its declared uncompressed size"), and the sink
//! counts the bytes it writes, so a lying directory cannot get past the byte cap either.

use std::fs::File;
use std::io::BufReader;

use super::sink::DiskSink;
use super::zip_directory::check_directory;
use super::{ArchiveError, UnpackLimits};

const FILE_TYPE_MASK: u32 = 0o170000;
const REGULAR_FILE: u32 = 0o100000;
const DIRECTORY: u32 = 0o040000;
const SYMLINK: u32 = 0o120000;

pub fn unpack_zip(
    file: File,
    sink: &mut DiskSink<'_>,
    limits: &UnpackLimits,
) -> Result<(), ArchiveError> {
    let mut reader = BufReader::new(file);
    check_directory(&mut reader, limits)?;
    let mut archive =
        zip::ZipArchive::new(reader).map_err(|error| ArchiveError::Corrupt(error.to_string()))?;
    for index in 0..archive.len() {
        let mut entry = archive
            .by_index(index)
            .map_err(|error| ArchiveError::Corrupt(format!("entry {index}: {error}")))?;
        // The raw bytes, which `check_directory` found to be UTF-8: the crate would decode a
        // name without the UTF-8 flag as CP437.
        let name = String::from_utf8_lossy(entry.name_raw()).into_owned();
        if entry.encrypted() {
            return Err(ArchiveError::Corrupt(format!(
                "{name}: encrypted entries are not supported"
            )));
        }
        let file_type = entry.unix_mode().map(|mode| mode & FILE_TYPE_MASK);
        match file_type {
            Some(SYMLINK) => return Err(ArchiveError::Link { entry: name }),
            Some(0 | REGULAR_FILE | DIRECTORY) | None => {}
            Some(other) => {
                return Err(ArchiveError::SpecialFile {
                    entry: name,
                    kind: format!("file type {other:o}"),
                });
            }
        }
        if entry.is_dir() || file_type == Some(DIRECTORY) {
            sink.create_dir(&name)?;
        } else {
            sink.write_file(&name, &mut entry)?;
        }
    }
    Ok(())
}
