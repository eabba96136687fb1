//! The zip's central directory, read and checked before anything is unpacked.
//!
//! Entry names are checked here because the `zip` crate's index is keyed by name, so a second
//! entry of the same name silently replaces the first, and names without the UTF-8 flag are
//! decoded as CP437 (garbling UTF-8 bytes): scene archives must have unique names that are valid
//! UTF-8. The entry count and the declared unpacked sizes are checked here too, so a zip bomb or
//! an archive of too many entries is refused from a few kilobytes of directory instead of after
//! gigabytes of inflating (issue 39, defect 9). Declared sizes can lie, so the `zip` crate's
//! reader still refuses an entry that inflates past its declared size and the sink still counts
//! the bytes it writes.

use std::collections::HashSet;
use std::io::{Read, Seek, SeekFrom};

use super::{ArchiveError, UnpackLimits};

const END_SIGNATURE: u32 = 0x0605_4b50;
const ZIP64_LOCATOR_SIGNATURE: u32 = 0x0706_4b50;
const ZIP64_END_SIGNATURE: u32 = 0x0606_4b50;
const CENTRAL_SIGNATURE: u32 = 0x0201_4b50;
/// The extra field that holds an entry's 64-bit sizes when its 32-bit fields say `u32::MAX`.
const ZIP64_EXTRA_ID: u16 = 0x0001;
const END_LEN: u64 = 22;
const CENTRAL_ENTRY_LEN: usize = 46;
/// The end record plus the longest comment it may carry.
const END_SEARCH_LEN: u64 = END_LEN + u16::MAX as u64;
/// A central directory beyond this is not a scene archive we would accept anyway.
const MAX_DIRECTORY_BYTES: u64 = 512 << 20;

/// Where the central directory is and how many entries it declares.
struct EndRecord {
    entries: u64,
    start: u64,
    size: u64,
}

/// Fails when the archive declares more entries or more unpacked bytes than `limits` allow, or
/// holds an entry name that is not valid UTF-8 or that an earlier entry already has. Reads only
/// the end record and the central directory; the entry count is checked before the directory is
/// read.
pub fn check_directory(
    reader: &mut (impl Read + Seek),
    limits: &UnpackLimits,
) -> Result<(), ArchiveError> {
    let end = read_end_record(reader)?;
    if end.entries > limits.max_files {
        return Err(ArchiveError::DeclaresTooManyEntries {
            declared: end.entries,
            limit: limits.max_files,
        });
    }
    if end.size > MAX_DIRECTORY_BYTES || end.start.saturating_add(end.size) > archive_len(reader)? {
        return Err(corrupt("central directory out of bounds"));
    }
    let directory = read_at(reader, end.start, end.size)?;
    let mut seen = HashSet::new();
    let mut declared_bytes = 0u64;
    let mut offset = 0usize;
    let mut index = 0u64;
    while offset + CENTRAL_ENTRY_LEN <= directory.len() {
        if u32_at(&directory, offset) != CENTRAL_SIGNATURE {
            return Err(corrupt("central directory entry without its signature"));
        }
        // The end record's count may understate what the directory holds.
        index += 1;
        if index > limits.max_files {
            return Err(ArchiveError::TooManyFiles {
                limit: limits.max_files,
            });
        }
        let name_len = usize::from(u16_at(&directory, offset + 28));
        let extra_len = usize::from(u16_at(&directory, offset + 30));
        let comment_len = usize::from(u16_at(&directory, offset + 32));
        let name_at = offset + CENTRAL_ENTRY_LEN;
        let extra_at = name_at + name_len;
        let (Some(name), Some(extra)) = (
            directory.get(name_at..extra_at),
            directory.get(extra_at..extra_at + extra_len),
        ) else {
            return Err(corrupt("central directory entry runs past its end"));
        };
        let name = check_name(name, index - 1, &mut seen)?;
        let size = declared_size(u32_at(&directory, offset + 24), extra)
            .ok_or_else(|| corrupt(&format!("{name}: zip64 size missing from its entry")))?;
        declared_bytes = declared_bytes.saturating_add(size);
        offset = extra_at + extra_len + comment_len;
    }
    if declared_bytes > limits.max_unpacked_bytes {
        return Err(ArchiveError::DeclaresTooManyBytes {
            declared: declared_bytes,
            limit: limits.max_unpacked_bytes,
        });
    }
    Ok(())
}

fn check_name<'a>(
    name: &'a [u8],
    index: u64,
    seen: &mut HashSet<&'a str>,
) -> Result<&'a str, ArchiveError> {
    let Ok(name) = std::str::from_utf8(name) else {
        return Err(ArchiveError::BadName(format!(
            "entry {index} ({}): name is not valid UTF-8; re-create the archive with UTF-8 names",
            String::from_utf8_lossy(name)
        )));
    };
    if !seen.insert(name) {
        return Err(ArchiveError::BadName(format!(
            "{name}: duplicate entry name (the archive holds it more than once)"
        )));
    }
    Ok(name)
}

/// An entry's declared unpacked size: the 32-bit field, or the zip64 extra field's first value
/// when the 32-bit field is saturated (the zip64 field lists the uncompressed size first).
fn declared_size(size32: u32, extra: &[u8]) -> Option<u64> {
    if size32 != u32::MAX {
        return Some(u64::from(size32));
    }
    let mut at = 0usize;
    while at + 4 <= extra.len() {
        let id = u16_at(extra, at);
        let len = usize::from(u16_at(extra, at + 2));
        if id == ZIP64_EXTRA_ID && len >= 8 {
            return extra.get(at + 4..at + 12).map(|_| u64_at(extra, at + 4));
        }
        at += 4 + len;
    }
    None
}

/// The end record (and its zip64 version), found by searching back from the archive's end.
fn read_end_record(reader: &mut (impl Read + Seek)) -> Result<EndRecord, ArchiveError> {
    let length = archive_len(reader)?;
    let tail_len = length.min(END_SEARCH_LEN);
    let tail = read_at(reader, length - tail_len, tail_len)?;
    let end = (0..tail.len().saturating_sub(END_LEN as usize - 1))
        .rev()
        .find(|&at| u32_at(&tail, at) == END_SIGNATURE)
        .ok_or_else(|| corrupt("no end of central directory record"))?;
    let mut record = EndRecord {
        entries: u64::from(u16_at(&tail, end + 10)),
        size: u64::from(u32_at(&tail, end + 12)),
        start: u64::from(u32_at(&tail, end + 16)),
    };
    let saturated = record.entries == u64::from(u16::MAX)
        || record.size == u64::from(u32::MAX)
        || record.start == u64::from(u32::MAX);
    if saturated && end >= 20 {
        let locator = end - 20;
        if u32_at(&tail, locator) == ZIP64_LOCATOR_SIGNATURE {
            let record_at = u64_at(&tail, locator + 8);
            let zip64 = read_at(reader, record_at, 56)?;
            if u32_at(&zip64, 0) != ZIP64_END_SIGNATURE {
                return Err(corrupt("zip64 end record without its signature"));
            }
            record = EndRecord {
                entries: u64_at(&zip64, 32),
                size: u64_at(&zip64, 40),
                start: u64_at(&zip64, 48),
            };
        }
    }
    Ok(record)
}

fn archive_len(reader: &mut impl Seek) -> Result<u64, ArchiveError> {
    reader.seek(SeekFrom::End(0)).map_err(read_error)
}

fn read_at(reader: &mut (impl Read + Seek), at: u64, len: u64) -> Result<Vec<u8>, ArchiveError> {
    reader.seek(SeekFrom::Start(at)).map_err(read_error)?;
    let mut bytes = Vec::new();
    reader
        .take(len)
        .read_to_end(&mut bytes)
        .map_err(read_error)?;
    if bytes.len() as u64 != len {
        return Err(corrupt("central directory is truncated"));
    }
    Ok(bytes)
}

fn u16_at(bytes: &[u8], at: usize) -> u16 {
    bytes
        .get(at..at + 2)
        .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]))
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    bytes
        .get(at..at + 4)
        .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

fn u64_at(bytes: &[u8], at: usize) -> u64 {
    bytes.get(at..at + 8).map_or(0, |b| {
        u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])
    })
}

fn corrupt(what: &str) -> ArchiveError {
    ArchiveError::Corrupt(what.to_string())
}

fn read_error(error: std::io::Error) -> ArchiveError {
    ArchiveError::Corrupt(format!("cannot read the zip directory: {error}"))
}
