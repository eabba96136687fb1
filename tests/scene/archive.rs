//! Archive unpacking: every accepted kind and every rejection, with archives built in the test.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use segsplat_scene::{ArchiveError, InputErrorClass, UnpackLimits, UnpackStats, unpack_archive};
use zip::write::SimpleFileOptions;

use crate::zip_bomb;

fn limits() -> UnpackLimits {
    UnpackLimits {
        max_unpacked_bytes: 1 << 20,
        max_files: 100,
    }
}

struct Workspace {
    _dir: tempfile::TempDir,
    dest: PathBuf,
}

fn unpack(bytes: &[u8]) -> (Result<UnpackStats, ArchiveError>, Workspace) {
    unpack_with(bytes, &limits())
}

fn unpack_with(
    bytes: &[u8],
    limits: &UnpackLimits,
) -> (Result<UnpackStats, ArchiveError>, Workspace) {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("upload.bin");
    fs::write(&archive, bytes).unwrap();
    let dest = dir.path().join("out");
    fs::create_dir(&dest).unwrap();
    let result = unpack_archive(&archive, &dest, limits);
    (result, Workspace { _dir: dir, dest })
}

fn zip_of(files: &[(&str, &[u8])]) -> Vec<u8> {
    let mut writer = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, content) in files {
        writer
            .start_file(*name, SimpleFileOptions::default())
            .unwrap();
        writer.write_all(content).unwrap();
    }
    writer.finish().unwrap().into_inner()
}

/// A tar entry written with a raw header so unsafe names reach the archive unchanged.
fn raw_tar_entry(
    builder: &mut tar::Builder<Vec<u8>>,
    name: &str,
    kind: tar::EntryType,
    data: &[u8],
) {
    let mut header = tar::Header::new_gnu();
    header.as_old_mut().name[..name.len()].copy_from_slice(name.as_bytes());
    header.set_entry_type(kind);
    header.set_size(data.len() as u64);
    header.set_mode(0o644);
    header.set_cksum();
    builder.append(&header, data).unwrap();
}

fn tar_of(entries: &[(&str, tar::EntryType, &[u8])]) -> Vec<u8> {
    let mut builder = tar::Builder::new(Vec::new());
    for (name, kind, data) in entries {
        raw_tar_entry(&mut builder, name, *kind, data);
    }
    builder.into_inner().unwrap()
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    encoder.write_all(bytes).unwrap();
    encoder.finish().unwrap()
}

fn read(dest: &Path, relative: &str) -> Vec<u8> {
    fs::read(dest.join(relative)).unwrap()
}

#[test]
fn zip_tar_and_tar_gz_unpack_to_the_same_files() {
    let files: [(&str, &[u8]); 2] = [
        ("scene/images/a.png", b"aaa"),
        ("scene/notes.txt", b"hello"),
    ];
    let tar = tar_of(&[
        ("scene/", tar::EntryType::Directory, b""),
        ("scene/images/a.png", tar::EntryType::Regular, b"aaa"),
        ("scene/notes.txt", tar::EntryType::Regular, b"hello"),
    ]);
    for bytes in [zip_of(&files), tar.clone(), gzip(&tar)] {
        let (result, workspace) = unpack(&bytes);
        let stats = result.unwrap();
        assert_eq!(stats.files, 2);
        assert_eq!(stats.bytes, 8);
        assert_eq!(read(&workspace.dest, "scene/images/a.png"), b"aaa");
        assert_eq!(read(&workspace.dest, "scene/notes.txt"), b"hello");
    }
}

#[test]
fn empty_zip_unpacks_to_nothing() {
    let bytes = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()))
        .finish()
        .unwrap()
        .into_inner();
    let (result, workspace) = unpack(&bytes);
    assert_eq!(result.unwrap().files, 0);
    assert_eq!(fs::read_dir(&workspace.dest).unwrap().count(), 0);
}

#[test]
fn unknown_bytes_are_an_unsupported_kind() {
    let (result, _) = unpack(b"%PDF-1.7 this is not an archive at all");
    let error = result.unwrap_err();
    assert!(matches!(error, ArchiveError::UnsupportedKind), "{error}");
    assert_eq!(error.class(), InputErrorClass::UnsupportedFormat);
    // A gzip of something that is not a tar is not a scene archive either.
    let (result, _) = unpack(&gzip(&[b'x'; 2000]));
    assert!(matches!(result, Err(ArchiveError::UnsupportedKind)));
}

#[test]
fn zip_slip_names_are_rejected() {
    for name in [
        "../evil.txt",
        "a/../../evil.txt",
        "/etc/evil.txt",
        "..\\evil.txt",
        "C:/evil.txt",
    ] {
        let (result, workspace) = unpack(&zip_of(&[("ok.txt", b"ok"), (name, b"evil")]));
        let error = result.unwrap_err();
        assert!(
            matches!(error, ArchiveError::UnsafePath { .. }),
            "{name}: {error}"
        );
        assert_eq!(error.class(), InputErrorClass::Malformed);
        assert!(!workspace.dest.parent().unwrap().join("evil.txt").exists());
    }
}

#[test]
fn tar_slip_names_are_rejected() {
    for name in ["../evil.txt", "/abs/evil.txt", "a/../../evil.txt"] {
        let bytes = tar_of(&[(name, tar::EntryType::Regular, b"evil")]);
        let (result, _) = unpack(&bytes);
        assert!(
            matches!(result, Err(ArchiveError::UnsafePath { .. })),
            "{name}: {result:?}"
        );
    }
}

#[test]
fn zip_symlinks_are_rejected() {
    let mut writer = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    writer
        .add_symlink("link", "/etc/passwd", SimpleFileOptions::default())
        .unwrap();
    let bytes = writer.finish().unwrap().into_inner();
    let (result, workspace) = unpack(&bytes);
    let error = result.unwrap_err();
    assert!(matches!(error, ArchiveError::Link { .. }), "{error}");
    assert!(fs::symlink_metadata(workspace.dest.join("link")).is_err());
}

#[test]
fn zip_special_files_are_rejected() {
    let mut writer = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let fifo_mode = 0o010644u32;
    let options = SimpleFileOptions::default()
        .system(zip::System::Unix)
        .external_attributes(fifo_mode << 16);
    writer.start_file("pipe", options).unwrap();
    let bytes = writer.finish().unwrap().into_inner();
    let (result, _) = unpack(&bytes);
    assert!(
        matches!(result, Err(ArchiveError::SpecialFile { .. })),
        "{result:?}"
    );
}

#[test]
fn tar_links_and_devices_are_rejected() {
    for (kind, expect_link) in [
        (tar::EntryType::Symlink, true),
        (tar::EntryType::Link, true),
        (tar::EntryType::Char, false),
        (tar::EntryType::Block, false),
        (tar::EntryType::Fifo, false),
    ] {
        let bytes = tar_of(&[("thing", kind, b"")]);
        let (result, _) = unpack(&bytes);
        let error = result.unwrap_err();
        if expect_link {
            assert!(
                matches!(error, ArchiveError::Link { .. }),
                "{kind:?}: {error}"
            );
        } else {
            assert!(
                matches!(error, ArchiveError::SpecialFile { .. }),
                "{kind:?}: {error}"
            );
        }
    }
}

/// Everything under `dest`, for asserting that a refusal wrote nothing.
fn entries(dest: &Path) -> Vec<PathBuf> {
    fs::read_dir(dest)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .collect()
}

/// Unpacks `bytes`, which must be refused as too large, with `message`, before anything is
/// written; returns the error.
fn refused_before_unpacking(bytes: &[u8], limits: &UnpackLimits, message: &str) -> ArchiveError {
    let (result, workspace) = unpack_with(bytes, limits);
    let error = result.unwrap_err();
    assert_eq!(error.to_string(), message);
    assert_eq!(error.class(), InputErrorClass::TooLarge);
    assert_eq!(entries(&workspace.dest), Vec::<PathBuf>::new());
    error
}

/// A zip bomb is refused from its central directory's declared sizes, before anything is
/// inflated or written. Before issue 39's fix it was inflated until the byte cap (a 9 GiB bomb
/// was read to ~8 GiB before its 413), leaving the cap's worth of a file behind.
#[test]
fn zip_bombs_are_refused_from_the_directory_before_unpacking() {
    // 2 MiB of zeros deflates to a few KiB; the cap is 1 MiB.
    let zeros = vec![0u8; 2 << 20];
    let bytes = zip_of(&[("bomb.bin", &zeros)]);
    assert!(bytes.len() < 64 * 1024);
    let error = refused_before_unpacking(
        &bytes,
        &limits(),
        "the zip's directory declares 2097152 bytes unpacked, more than the 1048576 allowed",
    );
    assert!(matches!(error, ArchiveError::DeclaresTooManyBytes { .. }));

    // The 9 GiB bomb's shape: zip64 sizes in the directory, against the service's 8 GiB.
    let bomb = zip_bomb::zip64_declaring("bomb.bin", b"zeros", 9 << 30);
    let service_limits = UnpackLimits {
        max_unpacked_bytes: 8 << 30,
        max_files: 100_000,
    };
    refused_before_unpacking(
        &bomb,
        &service_limits,
        "the zip's directory declares 9663676416 bytes unpacked, more than the 8589934592 allowed",
    );
}

/// Declared sizes can lie: an entry whose headers understate it is refused once it inflates
/// past its declared size (the directory's total was what the cap checked), and a tar, which has
/// no directory, is bounded by the bytes written.
#[test]
fn byte_cap_counts_written_bytes_for_lying_headers() {
    let zeros = vec![0u8; 2 << 20];
    let mut bytes = zip_of(&[("bomb.bin", &zeros)]);
    // Patch the uncompressed size (local header +22, central entry +24) down to 1000.
    let end = bytes.len() - 22;
    let directory_at = u32::from_le_bytes(bytes[end + 16..end + 20].try_into().unwrap()) as usize;
    bytes[22..26].copy_from_slice(&1000u32.to_le_bytes());
    bytes[directory_at + 24..directory_at + 28].copy_from_slice(&1000u32.to_le_bytes());
    let roomy = UnpackLimits {
        max_unpacked_bytes: 4 << 20,
        max_files: 100,
    };
    let (result, _) = unpack_with(&bytes, &roomy);
    let error = result.unwrap_err();
    assert!(
        error
            .to_string()
            .contains("bomb.bin: File is larger than its declared uncompressed size"),
        "{error}"
    );
    assert_eq!(error.class(), InputErrorClass::Malformed);

    let tar_bomb = gzip(&tar_of(&[("bomb.bin", tar::EntryType::Regular, &zeros)]));
    let (result, _) = unpack(&tar_bomb);
    assert!(matches!(result, Err(ArchiveError::TooManyBytes { .. })));
}

#[test]
fn byte_cap_spans_many_files() {
    let chunk = vec![7u8; 300 * 1024];
    // A zip's directory declares them all: refused from the sum.
    let bytes = zip_of(&[("a", &chunk), ("b", &chunk), ("c", &chunk), ("d", &chunk)]);
    let (result, _) = unpack(&bytes);
    assert!(
        matches!(
            result,
            Err(ArchiveError::DeclaresTooManyBytes {
                declared: 1228800,
                ..
            })
        ),
        "{result:?}"
    );
    // A tar has no directory: refused by the bytes written over the files.
    let names = ["a", "b", "c", "d"];
    let entries: Vec<(&str, tar::EntryType, &[u8])> = names
        .iter()
        .map(|name| (*name, tar::EntryType::Regular, &chunk[..]))
        .collect();
    let (result, _) = unpack(&tar_of(&entries));
    assert!(matches!(result, Err(ArchiveError::TooManyBytes { .. })));
}

#[test]
fn file_count_is_capped() {
    let names: Vec<String> = (0..6).map(|index| format!("f{index}")).collect();
    let files: Vec<(&str, &[u8])> = names
        .iter()
        .map(|name| (name.as_str(), &b"x"[..]))
        .collect();
    let small_limits = UnpackLimits {
        max_unpacked_bytes: 1 << 20,
        max_files: 5,
    };
    // A zip says how many entries it holds in its end record: refused from that, naming it,
    // before its directory is read.
    let zip = zip_of(&files);
    let error = refused_before_unpacking(
        &zip,
        &small_limits,
        "the zip declares 6 entries, more than the 5 allowed",
    );
    assert!(matches!(error, ArchiveError::DeclaresTooManyEntries { .. }));
    // An end record that understates the count: the directory's entries are counted too.
    let mut understated = zip;
    let end = understated.len() - 22;
    understated[end + 8..end + 12].copy_from_slice(&[1, 0, 1, 0]);
    let (result, workspace) = unpack_with(&understated, &small_limits);
    assert!(
        matches!(result, Err(ArchiveError::TooManyFiles { limit: 5 })),
        "{result:?}"
    );
    assert_eq!(entries(&workspace.dest), Vec::<PathBuf>::new());

    let entries: Vec<(&str, tar::EntryType, &[u8])> = names
        .iter()
        .map(|name| (name.as_str(), tar::EntryType::Regular, &b"x"[..]))
        .collect();
    let (result, _) = unpack_with(&tar_of(&entries), &small_limits);
    assert!(matches!(
        result,
        Err(ArchiveError::TooManyFiles { limit: 5 })
    ));
}

#[test]
fn truncated_archives_are_corrupt() {
    let content = vec![42u8; 5000];
    let zip = zip_of(&[("a.bin", &content), ("b.bin", &content)]);
    let tar = tar_of(&[
        ("a.bin", tar::EntryType::Regular, &content),
        ("b.bin", tar::EntryType::Regular, &content),
    ]);
    let tar_gz = gzip(&tar);
    // Cut inside the data, and (for tar) exactly at an entry boundary, where the tar reader alone
    // would see a clean end.
    let a_entry_end = 512 + 5120;
    let cuts: [(&str, &[u8]); 4] = [
        ("zip", &zip[..zip.len() / 2]),
        ("tar mid-entry", &tar[..3000]),
        ("tar at boundary", &tar[..a_entry_end]),
        ("tar.gz", &tar_gz[..tar_gz.len() - 10]),
    ];
    for (label, bytes) in cuts {
        let (result, _) = unpack(bytes);
        let error = result.unwrap_err();
        assert!(
            matches!(error, ArchiveError::Corrupt(_)),
            "{label}: {error}"
        );
        assert_eq!(error.class(), InputErrorClass::Malformed);
    }
}

#[test]
fn duplicate_entries_do_not_overwrite() {
    let bytes = tar_of(&[
        ("a.txt", tar::EntryType::Regular, b"first"),
        ("a.txt", tar::EntryType::Regular, b"second"),
    ]);
    let (result, workspace) = unpack(&bytes);
    assert!(
        matches!(result, Err(ArchiveError::Corrupt(_))),
        "{result:?}"
    );
    assert_eq!(read(&workspace.dest, "a.txt"), b"first");
}

#[test]
fn long_tar_names_are_unpacked_under_their_full_name() {
    let long_name = format!("scene/{}/frame.png", "nested_folder_name".repeat(8));
    let mut builder = tar::Builder::new(Vec::new());
    let mut header = tar::Header::new_gnu();
    header.set_size(3);
    header.set_mode(0o644);
    builder
        .append_data(&mut header, &long_name, &b"png"[..])
        .unwrap();
    let (result, workspace) = unpack(&builder.into_inner().unwrap());
    assert_eq!(result.unwrap().files, 1);
    assert_eq!(read(&workspace.dest, &long_name), b"png");
}
