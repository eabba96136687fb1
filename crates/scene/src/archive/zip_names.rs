//! Entry names as the zip's central directory stores them, read before the `zip` crate indexes
//! the archive: that index is keyed by name, so a second entry of the same name silently replaces
//! the first, and names without the UTF-8 flag are decoded as CP437 (garbling UTF-8 bytes).
//! Scene archives must have unique names that are valid UTF-8.

use std::collections::HashSet;
use std::io::{Read, Seek, SeekFrom};

use super::ArchiveError;

const END_SIGNATURE: u32 = 0x0605_4b50;
const ZIP64_LOCATOR_SIGNATURE: u32 = 0x0706_4b50;
const ZIP64_END_SIGNATURE: u32 = 0x0606_4b50;
const CENTRAL_SIGNATURE: u32 = 0x0201_4b50;
const END_LEN: u64 = 22;
/// The end record plus the longest comment it may carry.
const END_SEARCH_LEN: u64 = END_LEN + u16::MAX as u64;
/// A central directory beyond this is not a scene archive we would accept anyway.
const MAX_DIRECTORY_BYTES: u64 = 512 << 20;

/// Fails on an entry name that is not valid UTF-8 or that an earlier entry already has.
pub fn check_entry_names(reader: &mut (impl Read + Seek)) -> Result<(), ArchiveError> {
    let directory = read_central_directory(reader)?;
    let mut seen = HashSet::new();
    let mut offset = 0usize;
    let mut index = 0usize;
    while offset + 46 <= directory.len() {
        if u32_at(&directory, offset) != CENTRAL_SIGNATURE {
            return Err(corrupt("central directory entry without its signature"));
        }
        let name_len = usize::from(u16_at(&directory, offset + 28));
        let extra_len = usize::from(u16_at(&directory, offset + 30));
        let comment_len = usize::from(u16_at(&directory, offset + 32));
        let name = directory
            .get(offset + 46..offset + 46 + name_len)
            .ok_or_else(|| corrupt("central directory entry runs past its end"))?;
        let Ok(name) = std::str::from_utf8(name) else {
            return Err(ArchiveError::BadName(format!(
                "entry {index} ({}): name is not valid UTF-8; re-create the archive with UTF-8 \
                 names",
                String::from_utf8_lossy(name)
            )));
        };
        if !seen.insert(name.to_string()) {
            return Err(ArchiveError::BadName(format!(
                "{name}: duplicate entry name (the archive holds it more than once)"
            )));
        }
        offset += 46 + name_len + extra_len + comment_len;
        index += 1;
    }
    Ok(())
}

/// The bytes of the central directory, found through the end record (and its zip64 version).
fn read_central_directory(reader: &mut (impl Read + Seek)) -> Result<Vec<u8>, ArchiveError> {
    let length = reader.seek(SeekFrom::End(0)).map_err(read_error)?;
    let tail_len = length.min(END_SEARCH_LEN);
    let tail = read_at(reader, length - tail_len, tail_len)?;
    let end = (0..tail.len().saturating_sub(END_LEN as usize - 1))
        .rev()
        .find(|&at| u32_at(&tail, at) == END_SIGNATURE)
        .ok_or_else(|| corrupt("no end of central directory record"))?;
    let mut size = u64::from(u32_at(&tail, end + 12));
    let mut start = u64::from(u32_at(&tail, end + 16));
    if (size == u64::from(u32::MAX) || start == u64::from(u32::MAX)) && end >= 20 {
        let locator = end - 20;
        if u32_at(&tail, locator) == ZIP64_LOCATOR_SIGNATURE {
            let record_at = u64_at(&tail, locator + 8);
            let record = read_at(reader, record_at, 56)?;
            if u32_at(&record, 0) != ZIP64_END_SIGNATURE {
                return Err(corrupt("zip64 end record without its signature"));
            }
            size = u64_at(&record, 40);
            start = u64_at(&record, 48);
        }
    }
    if size > MAX_DIRECTORY_BYTES || start.saturating_add(size) > length {
        return Err(corrupt("central directory out of bounds"));
    }
    read_at(reader, start, size)
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
