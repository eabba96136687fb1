//! The S3-compatible server the object-store tests run against: `scripts/test_servers.sh`
//! starts one (s3rver, from the npm registry) on 127.0.0.1 and exports where it is. Without it a
//! test skips with the reason, except in CI (`CI=true`), where a missing server fails.

use segsplat_service::config::BlobsConfig;

/// Blob settings for a fresh prefix of the test bucket, or `None` (skip) when no server is
/// configured outside CI.
pub fn s3_blobs(test: &str) -> Option<BlobsConfig> {
    let (Ok(endpoint), Ok(bucket)) = (
        std::env::var("SEGSPLAT_TEST_S3_ENDPOINT"),
        std::env::var("SEGSPLAT_TEST_S3_BUCKET"),
    ) else {
        let reason = "SEGSPLAT_TEST_S3_ENDPOINT and SEGSPLAT_TEST_S3_BUCKET are not set \
                      (scripts/test_servers.sh starts an S3-compatible server and sets them)";
        if std::env::var("CI").is_ok_and(|value| value == "true") {
            panic!("CI needs the S3-compatible test server: {reason}");
        }
        eprintln!("skipping {test}: {reason}");
        return None;
    };
    let credential = |name: &str| std::env::var(name).unwrap_or_else(|_| "S3RVER".to_string());
    Some(BlobsConfig {
        access_key_id: Some(credential("SEGSPLAT_TEST_S3_ACCESS_KEY_ID")),
        secret_access_key: Some(credential("SEGSPLAT_TEST_S3_SECRET_ACCESS_KEY")),
        request_timeout_secs: 30.0,
        max_retries: 2,
        ..s3rver_blobs(
            &endpoint,
            &format!("s3://{bucket}/{test}-{}", uuid::Uuid::new_v4().simple()),
        )
    })
}

/// Blob settings for s3rver at `endpoint` (its default credentials) and the bucket and prefix
/// `url` names; requests give up within 2 s and are not retried.
pub fn s3rver_blobs(endpoint: &str, url: &str) -> BlobsConfig {
    BlobsConfig {
        url: Some(url.to_string()),
        endpoint: Some(endpoint.to_string()),
        region: Some("us-east-1".into()),
        access_key_id: Some("S3RVER".into()),
        secret_access_key: Some("S3RVER".into()),
        allow_http: true,
        request_timeout_secs: 2.0,
        max_retries: 0,
        ..BlobsConfig::default()
    }
}

/// Blob settings for an S3 endpoint where nothing listens: every request fails fast.
pub fn unreachable_s3_blobs() -> BlobsConfig {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    BlobsConfig {
        access_key_id: Some("key".into()),
        secret_access_key: Some("secret".into()),
        ..s3rver_blobs(&format!("http://127.0.0.1:{port}"), "s3://nowhere/prefix")
    }
}
