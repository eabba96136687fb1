//! Tar and gzip-compressed tar entries through the `tar` crate.

use std::cell::Cell;
use std::fs::File;
use std::io::{self, BufReader, Cursor, Read};
use std::rc::Rc;

use flate2::read::MultiGzDecoder;
use tar::EntryType;

use super::ArchiveError;
use super::sink::DiskSink;
use super::sniff::{TAR_BLOCK_LEN, looks_like_tar_header};

pub fn unpack_tar(file: File, sink: &mut DiskSink<'_>) -> Result<(), ArchiveError> {
    unpack_tar_stream(BufReader::new(file), sink).map(|_| ())
}

/// The decompressed stream must itself look like a tar (a gzip of anything else is not a scene
/// archive); after the tar end marker the rest of the stream is read so gzip verifies its
/// checksum and length trailer, which catches truncation inside the padding.
pub fn unpack_tar_gz(file: File, sink: &mut DiskSink<'_>) -> Result<(), ArchiveError> {
    let mut decoder = MultiGzDecoder::new(BufReader::new(file));
    let mut head = Vec::with_capacity(TAR_BLOCK_LEN);
    (&mut decoder)
        .take(TAR_BLOCK_LEN as u64)
        .read_to_end(&mut head)
        .map_err(|error| ArchiveError::Corrupt(format!("gzip stream: {error}")))?;
    if !looks_like_tar_header(&head) {
        return Err(ArchiveError::UnsupportedKind);
    }
    let rest = unpack_tar_stream(Cursor::new(head).chain(decoder), sink)?;
    let mut rest = rest;
    sink.drain(&mut rest)
}

/// Unpacks every entry; returns the reader positioned after the end-of-archive marker.
fn unpack_tar_stream<R: Read>(
    reader: R,
    sink: &mut DiskSink<'_>,
) -> Result<EofWatch<R>, ArchiveError> {
    let watched = EofWatch::new(reader);
    let hit_eof = watched.hit_eof.clone();
    let mut archive = tar::Archive::new(watched);
    let entries = archive
        .entries()
        .map_err(|error| ArchiveError::Corrupt(error.to_string()))?;
    for entry in entries {
        let mut entry = entry.map_err(|error| ArchiveError::Corrupt(error.to_string()))?;
        let name = match std::str::from_utf8(&entry.path_bytes()) {
            Ok(name) => name.to_string(),
            Err(_) => {
                return Err(ArchiveError::UnsafePath {
                    entry: String::from_utf8_lossy(&entry.path_bytes()).into_owned(),
                });
            }
        };
        match entry.header().entry_type() {
            EntryType::Regular | EntryType::Continuous => sink.write_file(&name, &mut entry)?,
            EntryType::Directory => sink.create_dir(&name)?,
            EntryType::Symlink | EntryType::Link => {
                return Err(ArchiveError::Link { entry: name });
            }
            // Global pax headers carry metadata for following entries, no content of their own.
            EntryType::XGlobalHeader => {}
            other => {
                return Err(ArchiveError::SpecialFile {
                    entry: name,
                    kind: special_kind_name(other),
                });
            }
        }
    }
    // The tar crate treats a clean end of input between entries as the end of the archive; a
    // complete archive ends with zero blocks instead, so reaching EOF first means truncation.
    if hit_eof.get() {
        return Err(ArchiveError::Corrupt(
            "tar ends without its end-of-archive marker".to_string(),
        ));
    }
    Ok(archive.into_inner())
}

fn special_kind_name(entry_type: EntryType) -> String {
    match entry_type {
        EntryType::Char => "character device".to_string(),
        EntryType::Block => "block device".to_string(),
        EntryType::Fifo => "fifo".to_string(),
        EntryType::GNUSparse => "sparse file".to_string(),
        other => format!("tar entry type {:?}", other.as_byte() as char),
    }
}

/// Remembers whether the underlying reader ever reported end of input.
struct EofWatch<R> {
    inner: R,
    hit_eof: Rc<Cell<bool>>,
}

impl<R> EofWatch<R> {
    fn new(inner: R) -> Self {
        Self {
            inner,
            hit_eof: Rc::new(Cell::new(false)),
        }
    }
}

impl<R: Read> Read for EofWatch<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let read = self.inner.read(buf)?;
        if read == 0 && !buf.is_empty() {
            self.hit_eof.set(true);
        }
        Ok(read)
    }
}
