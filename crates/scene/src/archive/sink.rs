//! Writing validated entries under the destination directory while enforcing the limits.

use std::fs::{self, OpenOptions};
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};

use super::{ArchiveError, UnpackLimits, UnpackStats, safe_relative_path};

const COPY_BUFFER_LEN: usize = 64 * 1024;

/// The unpack destination with running counts; every archive reader writes through it.
pub struct DiskSink<'a> {
    dest: &'a Path,
    limits: &'a UnpackLimits,
    entries: u64,
    stats: UnpackStats,
}

impl<'a> DiskSink<'a> {
    pub fn new(dest: &'a Path, limits: &'a UnpackLimits) -> Self {
        Self {
            dest,
            limits,
            entries: 0,
            stats: UnpackStats::default(),
        }
    }

    pub fn stats(&self) -> UnpackStats {
        self.stats.clone()
    }

    pub fn create_dir(&mut self, entry: &str) -> Result<(), ArchiveError> {
        let Some(relative) = safe_relative_path(entry)? else {
            return Ok(());
        };
        self.count_entry()?;
        let path = self.dest.join(&relative);
        fs::create_dir_all(&path).map_err(|source| conflict_or_io(entry, &path, source))
    }

    /// Streams `data` into a new file for `entry`. Read errors mean a broken archive; write
    /// errors are ours.
    pub fn write_file(&mut self, entry: &str, data: &mut impl Read) -> Result<(), ArchiveError> {
        let Some(relative) = safe_relative_path(entry)? else {
            return Err(ArchiveError::UnsafePath {
                entry: entry.to_string(),
            });
        };
        self.count_entry()?;
        let path = self.dest.join(&relative);
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(|source| conflict_or_io(entry, parent, source))?;
        }
        let mut file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|source| conflict_or_io(entry, &path, source))?;
        // No fsync: the unpacked tree is scratch, read back by this process through the page
        // cache and removed after the upload; a crash loses the upload either way. One fsync a
        // file cost ~2 ms each, minutes for an archive of 50k small files (issue 39, defect 9).
        self.copy_bounded(entry, data, &mut file, &path)?;
        self.stats.files += 1;
        Ok(())
    }

    /// Reads `data` to its end without keeping it (trailing padding after a tar's end marker,
    /// read so the gzip checksum gets verified). Not counted as unpacked bytes, but bounded by
    /// the same cap so a compressed stream cannot make us spin on endless padding.
    pub fn drain(&self, data: &mut impl Read) -> Result<(), ArchiveError> {
        let limit = self.limits.max_unpacked_bytes;
        let drained = io::copy(&mut data.take(limit.saturating_add(1)), &mut io::sink())
            .map_err(|error| ArchiveError::Corrupt(format!("after the tar end marker: {error}")))?;
        if drained > limit {
            return Err(ArchiveError::TooManyBytes { limit });
        }
        Ok(())
    }

    fn count_entry(&mut self) -> Result<(), ArchiveError> {
        self.entries += 1;
        if self.entries > self.limits.max_files {
            return Err(ArchiveError::TooManyFiles {
                limit: self.limits.max_files,
            });
        }
        Ok(())
    }

    fn copy_bounded(
        &mut self,
        entry: &str,
        data: &mut impl Read,
        out: &mut impl Write,
        path: &Path,
    ) -> Result<(), ArchiveError> {
        let mut buffer = vec![0u8; COPY_BUFFER_LEN];
        loop {
            let read = match data.read(&mut buffer) {
                Ok(0) => return Ok(()),
                Ok(read) => read,
                Err(error) if error.kind() == io::ErrorKind::Interrupted => continue,
                Err(error) => {
                    return Err(ArchiveError::Corrupt(format!("{entry}: {error}")));
                }
            };
            self.stats.bytes += read as u64;
            if self.stats.bytes > self.limits.max_unpacked_bytes {
                return Err(ArchiveError::TooManyBytes {
                    limit: self.limits.max_unpacked_bytes,
                });
            }
            out.write_all(&buffer[..read])
                .map_err(|source| write_error(path, source))?;
        }
    }
}

fn write_error(path: &Path, source: io::Error) -> ArchiveError {
    ArchiveError::Io {
        context: format!("writing {}", path.display()),
        source,
    }
}

/// Creating a path fails because of the archive (duplicate entry, a file where a folder must go)
/// or because of the machine; only the latter is an internal error.
fn conflict_or_io(entry: &str, path: &Path, source: io::Error) -> ArchiveError {
    match source.kind() {
        io::ErrorKind::AlreadyExists | io::ErrorKind::NotADirectory => ArchiveError::Corrupt(
            format!("{entry}: clashes with an earlier entry of the same name"),
        ),
        _ => ArchiveError::Io {
            context: format!("creating {}", PathBuf::from(path).display()),
            source,
        },
    }
}
