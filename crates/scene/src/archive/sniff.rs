//! Telling zip, tar and tar.gz apart by their first bytes, never by file name.

use std::io::Read;

use super::ArchiveError;

/// Length of one tar block (and header).
pub const TAR_BLOCK_LEN: usize = 512;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArchiveKind {
    Zip,
    Tar,
    /// gzip-compressed; the decompressed stream is checked to be a tar when unpacking.
    TarGz,
}

/// Reads up to one tar block from `reader` and names the archive kind, or `UnsupportedKind`.
pub fn sniff_kind(reader: &mut impl Read) -> Result<ArchiveKind, ArchiveError> {
    let mut head = Vec::with_capacity(TAR_BLOCK_LEN);
    reader
        .take(TAR_BLOCK_LEN as u64)
        .read_to_end(&mut head)
        .map_err(|source| ArchiveError::Io {
            context: "reading the archive header".to_string(),
            source,
        })?;
    if head.starts_with(b"PK\x03\x04") || head.starts_with(b"PK\x05\x06") {
        Ok(ArchiveKind::Zip)
    } else if head.starts_with(&[0x1f, 0x8b]) {
        Ok(ArchiveKind::TarGz)
    } else if looks_like_tar_header(&head) {
        Ok(ArchiveKind::Tar)
    } else {
        Err(ArchiveError::UnsupportedKind)
    }
}

/// A full block that is either an all-zero end marker (an empty tar), carries the POSIX `ustar`
/// magic, or is an old-style (v7) header whose checksum adds up.
pub fn looks_like_tar_header(block: &[u8]) -> bool {
    if block.len() < TAR_BLOCK_LEN {
        return false;
    }
    if block[..TAR_BLOCK_LEN].iter().all(|byte| *byte == 0) {
        return true;
    }
    if &block[257..262] == b"ustar" {
        return true;
    }
    let stored = match parse_octal(&block[148..156]) {
        Some(value) => value,
        None => return false,
    };
    let computed: u64 = block[..TAR_BLOCK_LEN]
        .iter()
        .enumerate()
        .map(|(index, byte)| {
            if (148..156).contains(&index) {
                u64::from(b' ')
            } else {
                u64::from(*byte)
            }
        })
        .sum();
    stored == computed
}

/// Tar numeric fields: octal digits, padded with spaces or NULs.
fn parse_octal(field: &[u8]) -> Option<u64> {
    let digits: Vec<u8> = field
        .iter()
        .copied()
        .skip_while(|byte| *byte == b' ')
        .take_while(|byte| (b'0'..=b'7').contains(byte))
        .collect();
    if digits.is_empty() {
        return None;
    }
    digits.iter().try_fold(0u64, |value, digit| {
        value.checked_mul(8)?.checked_add(u64::from(digit - b'0'))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn magic_bytes_pick_the_kind() {
        let kind = |bytes: &[u8]| sniff_kind(&mut &bytes[..]);
        assert_eq!(kind(b"PK\x03\x04rest").unwrap(), ArchiveKind::Zip);
        assert_eq!(kind(b"PK\x05\x06").unwrap(), ArchiveKind::Zip);
        assert_eq!(kind(&[0x1f, 0x8b, 8, 0]).unwrap(), ArchiveKind::TarGz);
        assert_eq!(kind(&[0u8; 1024]).unwrap(), ArchiveKind::Tar);
        assert!(matches!(
            kind(b"just some text that is not an archive"),
            Err(ArchiveError::UnsupportedKind)
        ));
        assert!(matches!(
            kind(&[7u8; 600]),
            Err(ArchiveError::UnsupportedKind)
        ));
    }

    #[test]
    fn old_style_tar_header_is_recognised_by_checksum() {
        let mut header = tar::Header::new_old();
        header.set_path("a.txt").unwrap();
        header.set_size(3);
        header.set_cksum();
        assert!(looks_like_tar_header(header.as_bytes()));
        let mut broken = *header.as_bytes();
        broken[0] ^= 1;
        assert!(!looks_like_tar_header(&broken));
    }
}
