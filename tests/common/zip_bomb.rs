//! A zip whose central directory declares a huge entry (zip64 sizes) around a few real bytes:
//! what a zip bomb's directory says, built without inflating or writing gigabytes. Included by
//! `#[path]` from tests that need none of the heavier shared modules.

const LOCAL_SIGNATURE: u32 = 0x0403_4b50;
const CENTRAL_SIGNATURE: u32 = 0x0201_4b50;
const END_SIGNATURE: u32 = 0x0605_4b50;
/// Version 4.5, the first with zip64; made by unix (3) so the mode bits are read.
const ZIP64_VERSION: u16 = 45;
const MADE_BY_UNIX: u16 = (3 << 8) | 45;
const REGULAR_FILE_MODE: u32 = 0o100_644;

/// One stored entry `name` holding `content`, whose local and central headers both declare
/// `declared` unpacked bytes through the zip64 extra field (the 32-bit sizes say `u32::MAX`).
pub fn zip64_declaring(name: &str, content: &[u8], declared: u64) -> Vec<u8> {
    let name_len = u16::try_from(name.len()).expect("a short name");
    // Zip64 extra: id 1, 16 bytes: uncompressed then compressed size.
    let mut extra = Vec::new();
    put16(&mut extra, 1);
    put16(&mut extra, 16);
    put64(&mut extra, declared);
    put64(&mut extra, content.len() as u64);

    let mut zip = Vec::new();
    put32(&mut zip, LOCAL_SIGNATURE);
    put16(&mut zip, ZIP64_VERSION);
    put16(&mut zip, 0); // flags
    put16(&mut zip, 0); // stored
    put32(&mut zip, 0); // time, date
    put32(&mut zip, 0); // crc (never checked: refused before reading)
    put32(&mut zip, u32::MAX);
    put32(&mut zip, u32::MAX);
    put16(&mut zip, name_len);
    put16(&mut zip, extra.len() as u16);
    zip.extend_from_slice(name.as_bytes());
    zip.extend_from_slice(&extra);
    zip.extend_from_slice(content);

    let directory_at = zip.len() as u32;
    put32(&mut zip, CENTRAL_SIGNATURE);
    put16(&mut zip, MADE_BY_UNIX);
    put16(&mut zip, ZIP64_VERSION);
    put16(&mut zip, 0); // flags
    put16(&mut zip, 0); // stored
    put32(&mut zip, 0); // time, date
    put32(&mut zip, 0); // crc
    put32(&mut zip, u32::MAX);
    put32(&mut zip, u32::MAX);
    put16(&mut zip, name_len);
    put16(&mut zip, extra.len() as u16);
    put16(&mut zip, 0); // comment
    put16(&mut zip, 0); // disk
    put16(&mut zip, 0); // internal attributes
    put32(&mut zip, REGULAR_FILE_MODE << 16);
    put32(&mut zip, 0); // local header offset
    zip.extend_from_slice(name.as_bytes());
    zip.extend_from_slice(&extra);
    let directory_len = zip.len() as u32 - directory_at;

    put32(&mut zip, END_SIGNATURE);
    put32(&mut zip, 0); // disks
    put16(&mut zip, 1);
    put16(&mut zip, 1);
    put32(&mut zip, directory_len);
    put32(&mut zip, directory_at);
    put16(&mut zip, 0); // comment
    zip
}

fn put16(out: &mut Vec<u8>, value: u16) {
    out.extend_from_slice(&value.to_le_bytes());
}

fn put32(out: &mut Vec<u8>, value: u32) {
    out.extend_from_slice(&value.to_le_bytes());
}

fn put64(out: &mut Vec<u8>, value: u64) {
    out.extend_from_slice(&value.to_le_bytes());
}
