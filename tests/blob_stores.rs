//! Both blob stores keep one contract: the local directory and an S3-compatible bucket (a real
//! server process, started by `scripts/test_servers.sh`). Keys, whole-segment prefixes, sorted
//! listings, NotFound, streamed multipart uploads of files larger than one part, downloads to a
//! path, deletes; and a store that cannot be reached reports itself unavailable.

mod common;

use std::io::Write;
use std::sync::Arc;

use common::object_store::{s3_blobs, unreachable_s3_blobs};
use common::s3rver::OwnS3rver;
use segsplat_service::store::{BlobError, BlobStore, LocalBlobStore, ObjectBlobStore};

fn check_contract(store: &dyn BlobStore) {
    store.put_bytes("scenes/a/files/x.txt", b"one").unwrap();
    store.put_bytes("scenes/a/files/sub/y.txt", b"two").unwrap();
    store.put_bytes("scenes/ab/z.txt", b"three").unwrap();
    store
        .put_bytes("scenes/a/files/x.txt", b"replaced")
        .unwrap();
    assert_eq!(
        store.get_bytes("scenes/a/files/x.txt").unwrap(),
        b"replaced"
    );
    assert_eq!(
        store.list_prefix("scenes/a").unwrap(),
        vec!["scenes/a/files/sub/y.txt", "scenes/a/files/x.txt"]
    );
    assert_eq!(store.list_prefix("scenes/a/").unwrap().len(), 2);
    assert!(store.exists("scenes/ab/z.txt").unwrap());
    assert!(!store.exists("scenes/a/none").unwrap());
    assert!(matches!(
        store.get_bytes("scenes/a/none"),
        Err(BlobError::NotFound { .. })
    ));
    assert!(matches!(
        store.put_bytes("../escape", b"x"),
        Err(BlobError::InvalidKey { .. })
    ));

    // A file of several upload parts, streamed up and down again.
    let mut large = tempfile::NamedTempFile::new().unwrap();
    let pattern: Vec<u8> = (0..(1u32 << 20)).map(|index| (index % 251) as u8).collect();
    for _ in 0..19 {
        large.write_all(&pattern).unwrap();
    }
    large.flush().unwrap();
    store
        .put_file("jobs/j/checkpoints/big.bin", large.path())
        .unwrap();
    let download = tempfile::tempdir().unwrap();
    let target = download.path().join("nested/big.bin");
    store
        .get_to_path("jobs/j/checkpoints/big.bin", &target)
        .unwrap();
    assert_eq!(
        std::fs::read(&target).unwrap(),
        std::fs::read(large.path()).unwrap()
    );

    assert_eq!(store.delete_prefix("scenes/a/").unwrap(), 2);
    assert!(!store.exists("scenes/a/files/x.txt").unwrap());
    assert!(store.exists("scenes/ab/z.txt").unwrap());
    assert_eq!(store.delete_prefix("jobs/j").unwrap(), 1);
    assert_eq!(store.delete_prefix("scenes").unwrap(), 1);
    assert!(store.list_prefix("").unwrap().is_empty());
}

#[test]
fn local_directory_keeps_the_contract() {
    let dir = tempfile::tempdir().unwrap();
    check_contract(&LocalBlobStore::open(dir.path()).unwrap());
}

#[test]
fn s3_bucket_keeps_the_contract() {
    let Some(config) = s3_blobs("contract") else {
        return;
    };
    let url = config.url.clone().unwrap();
    let store = Arc::new(ObjectBlobStore::open(&config, &url).unwrap());
    check_contract(store.as_ref());
}

#[tokio::test]
async fn s3_store_works_from_async_code_and_drops_there() {
    let Some(config) = s3_blobs("async") else {
        return;
    };
    let url = config.url.clone().unwrap();
    let store: Arc<dyn BlobStore> = Arc::new(ObjectBlobStore::open(&config, &url).unwrap());
    let inner = store.clone();
    tokio::task::spawn_blocking(move || inner.put_bytes("a/b", b"c").unwrap())
        .await
        .unwrap();
    assert_eq!(store.list_prefix("a").unwrap(), vec!["a/b"]);
    assert_eq!(store.delete_prefix("a").unwrap(), 1);
    // The last handle goes away inside the runtime; that must not panic.
    drop(store);
}

#[test]
fn an_unreachable_store_is_unavailable() {
    let config = unreachable_s3_blobs();
    let store = ObjectBlobStore::open(&config, "s3://nowhere/prefix").unwrap();
    let error = store.put_bytes("scenes/x/files/a", b"x").unwrap_err();
    assert!(matches!(&error, BlobError::Unavailable { .. }), "{error:?}");
    assert!(error.to_string().contains("unavailable"), "{error}");
    assert!(matches!(
        store.list_prefix("scenes"),
        Err(BlobError::Unavailable { .. })
    ));
}

/// An `https://` endpoint is spoken to in TLS (rustls, through object_store's reqwest client): the
/// first bytes the server gets are a TLS handshake record, and a server that then hangs up is
/// `Unavailable`.
#[test]
fn an_https_endpoint_is_spoken_to_in_tls() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let server = std::thread::spawn(move || {
        let (mut connection, _) = listener.accept().unwrap();
        let mut first = [0u8; 3];
        std::io::Read::read_exact(&mut connection, &mut first).unwrap();
        first
    });
    let config = segsplat_service::config::BlobsConfig {
        endpoint: Some(format!("https://127.0.0.1:{port}")),
        allow_http: false,
        max_retries: 0,
        ..unreachable_s3_blobs()
    };
    let store = ObjectBlobStore::open(&config, "s3://bucket/prefix").unwrap();
    let error = store.put_bytes("scenes/x/files/a", b"x").unwrap_err();
    assert!(matches!(&error, BlobError::Unavailable { .. }), "{error:?}");
    let first = server.join().unwrap();
    assert_eq!(first, [0x16, 0x03, 0x01], "a TLS handshake record");
}

/// A file whose upload fails at its final request (the one PUT of a small file, or the parts and
/// completion of a multipart one) while the server is down is an `Unavailable` error, not a
/// crashed client (object_store's writer panics when aborted after a failed shutdown), and the
/// store works again once the server is back.
#[test]
fn a_failed_final_put_is_unavailable_not_a_crash() {
    let Some(mut server) = OwnS3rver::start("a_failed_final_put_is_unavailable_not_a_crash") else {
        return;
    };
    let config = server.blobs("final-put");
    let url = config.url.clone().unwrap();
    let store = ObjectBlobStore::open(&config, &url).unwrap();
    let mut small = tempfile::NamedTempFile::new().unwrap();
    small.write_all(b"a checkpoint").unwrap();
    small.flush().unwrap();
    let mut large = tempfile::NamedTempFile::new().unwrap();
    large.write_all(&vec![7u8; 9 << 20]).unwrap();
    large.flush().unwrap();
    store.put_file("jobs/j/small", small.path()).unwrap();

    server.kill();
    for (key, file) in [("jobs/j/small", &small), ("jobs/j/large", &large)] {
        let error = store.put_file(key, file.path()).unwrap_err();
        assert!(matches!(&error, BlobError::Unavailable { .. }), "{error:?}");
        assert!(!error.to_string().contains("crashed"), "{key}: {error}");
    }

    server.restart();
    store.put_file("jobs/j/large", large.path()).unwrap();
    assert_eq!(
        store.list_prefix("jobs/j").unwrap(),
        vec!["jobs/j/large", "jobs/j/small"]
    );
}
