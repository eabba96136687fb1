//! Safe archive unpacking (zip, tar, tar.gz): no absolute paths, no `..`, no links or special
//! files, bounded size and entry count, truncation is an error.
//!
//! Archives come from untrusted uploads, so every entry name is checked by
//! [`entry_path::safe_relative_path`] before anything touches the disk, entries are streamed to
//! disk (never a whole archive in memory), and the byte cap counts bytes actually written, because
//! declared sizes in zip and tar headers can lie. A zip is refused from its central directory
//! when that declares more entries or bytes than the limits allow, before anything is unpacked.

mod entry_path;
mod sink;
mod sniff;
mod tar_unpack;
mod zip_directory;
mod zip_unpack;

use std::fs::File;
use std::path::Path;

use super::InputErrorClass;

pub use entry_path::safe_relative_path;
pub use sniff::{ArchiveKind, sniff_kind};

#[derive(Debug, Clone)]
pub struct UnpackLimits {
    /// Cap on bytes written to disk, summed over all files.
    pub max_unpacked_bytes: u64,
    /// Cap on entries created (files and directories both count).
    pub max_files: u64,
}

impl Default for UnpackLimits {
    /// 16 GiB and 100 000 entries: room for a few thousand full-resolution photos with masks.
    fn default() -> Self {
        Self {
            max_unpacked_bytes: 16 << 30,
            max_files: 100_000,
        }
    }
}

#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct UnpackStats {
    /// Regular files written.
    pub files: u64,
    /// Bytes written.
    pub bytes: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum ArchiveError {
    #[error("not a zip, tar or tar.gz archive")]
    UnsupportedKind,
    #[error("archive is truncated or corrupt: {0}")]
    Corrupt(String),
    #[error("{entry}: unsafe path (absolute or escaping the archive root)")]
    UnsafePath { entry: String },
    #[error("{entry}: {problem}")]
    PathTooLong { entry: String, problem: String },
    /// A zip entry name that is not valid UTF-8 or repeats an earlier one.
    #[error("{0}")]
    BadName(String),
    #[error("{entry}: links are not allowed in scene archives")]
    Link { entry: String },
    #[error("{entry}: {kind} entries are not allowed in scene archives (only files and folders)")]
    SpecialFile { entry: String, kind: String },
    #[error("archive unpacks to more than {limit} bytes")]
    TooManyBytes { limit: u64 },
    #[error("archive holds more than {limit} files")]
    TooManyFiles { limit: u64 },
    /// Read from the zip's central directory, before unpacking.
    #[error(
        "the zip's directory declares {declared} bytes unpacked, more than the {limit} allowed"
    )]
    DeclaresTooManyBytes { declared: u64, limit: u64 },
    /// Read from the zip's end record, before the directory.
    #[error("the zip declares {declared} entries, more than the {limit} allowed")]
    DeclaresTooManyEntries { declared: u64, limit: u64 },
    #[error("{context}: {source}")]
    Io {
        context: String,
        #[source]
        source: std::io::Error,
    },
}

impl ArchiveError {
    pub fn class(&self) -> InputErrorClass {
        match self {
            ArchiveError::UnsupportedKind => InputErrorClass::UnsupportedFormat,
            ArchiveError::Corrupt(_)
            | ArchiveError::UnsafePath { .. }
            | ArchiveError::PathTooLong { .. }
            | ArchiveError::BadName(_)
            | ArchiveError::Link { .. }
            | ArchiveError::SpecialFile { .. } => InputErrorClass::Malformed,
            ArchiveError::TooManyBytes { .. }
            | ArchiveError::TooManyFiles { .. }
            | ArchiveError::DeclaresTooManyBytes { .. }
            | ArchiveError::DeclaresTooManyEntries { .. } => InputErrorClass::TooLarge,
            ArchiveError::Io { .. } => InputErrorClass::Internal,
        }
    }
}

/// Unpacks `archive` (kind sniffed from its first bytes) into the existing empty directory `dest`.
///
/// On error, whatever was already written stays in `dest`; the caller owns `dest` and removes it.
pub fn unpack_archive(
    archive: &Path,
    dest: &Path,
    limits: &UnpackLimits,
) -> Result<UnpackStats, ArchiveError> {
    let open = || {
        File::open(archive).map_err(|source| ArchiveError::Io {
            context: format!("opening {}", archive.display()),
            source,
        })
    };
    let kind = sniff_kind(&mut open()?)?;
    let mut sink = sink::DiskSink::new(dest, limits);
    match kind {
        ArchiveKind::Zip => zip_unpack::unpack_zip(open()?, &mut sink, limits)?,
        ArchiveKind::Tar => tar_unpack::unpack_tar(open()?, &mut sink)?,
        ArchiveKind::TarGz => tar_unpack::unpack_tar_gz(open()?, &mut sink)?,
    }
    Ok(sink.stats())
}
