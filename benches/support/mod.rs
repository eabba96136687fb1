//! What the storage benches share: the S3-compatible test server's settings and the process's
//! peak memory.

use segsplat_service::config::BlobsConfig;

/// Settings for a fresh prefix of the test bucket (`scripts/test_servers.sh` starts s3rver and
/// exports where it is), or `None` after saying the bench is skipped.
pub fn s3_test_bucket(bench: &str) -> Option<BlobsConfig> {
    let (Ok(endpoint), Ok(bucket)) = (
        std::env::var("SEGSPLAT_TEST_S3_ENDPOINT"),
        std::env::var("SEGSPLAT_TEST_S3_BUCKET"),
    ) else {
        println!("{bench}: no S3-compatible server (run scripts/test_servers.sh); skipped");
        return None;
    };
    Some(BlobsConfig {
        url: Some(format!(
            "s3://{bucket}/bench-{}",
            uuid::Uuid::new_v4().simple()
        )),
        endpoint: Some(endpoint),
        region: Some("us-east-1".into()),
        access_key_id: Some("S3RVER".into()),
        secret_access_key: Some("S3RVER".into()),
        allow_http: true,
        request_timeout_secs: 300.0,
        ..BlobsConfig::default()
    })
}

/// The process's peak resident memory so far (`VmHWM`), in MiB.
pub fn peak_resident_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            status
                .lines()
                .find(|line| line.starts_with("VmHWM:"))
                .and_then(|line| line.split_whitespace().nth(1))
                .and_then(|kib| kib.parse::<f64>().ok())
        })
        .map_or(0.0, |kib| kib / 1024.0)
}
