//! An S3-compatible server of one test's own (s3rver, the binary `scripts/test_servers.sh`
//! runs), which the test may kill with SIGKILL and start again on the same port and data: a real
//! outage of the object store, not a stand-in. Without the binary a test skips with the reason,
//! except in CI (`CI=true`), where it fails.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use segsplat_service::config::BlobsConfig;

const BUCKET: &str = "segsplat-test";

pub struct OwnS3rver {
    binary: PathBuf,
    data: tempfile::TempDir,
    port: u16,
    child: Option<Child>,
}

fn s3rver_binary() -> PathBuf {
    let tools = std::env::var_os("SEGSPLAT_TOOLS_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(std::env::var_os("HOME").unwrap_or_default())
                .join(".cache/segsplat-tools")
        });
    tools.join("s3rver/node_modules/.bin/s3rver")
}

impl OwnS3rver {
    /// Starts one with a fresh bucket, or `None` (skip) when s3rver is not installed outside CI.
    pub fn start(test: &str) -> Option<OwnS3rver> {
        let binary = s3rver_binary();
        if !binary.exists() {
            let reason = format!(
                "no s3rver at {} (scripts/bootstrap.sh installs it)",
                binary.display()
            );
            if std::env::var("CI").is_ok_and(|value| value == "true") {
                panic!("{test} needs s3rver: {reason}");
            }
            eprintln!("skipping {test}: {reason}");
            return None;
        }
        let mut server = OwnS3rver {
            binary,
            data: tempfile::tempdir().expect("a folder for s3rver's data"),
            port: super::postgres::free_port(),
            child: None,
        };
        server.restart();
        Some(server)
    }

    /// Starts the server (again) on the same port and data, and waits until it answers.
    pub fn restart(&mut self) {
        assert!(self.child.is_none(), "s3rver is already running");
        let child = Command::new(&self.binary)
            .arg("--directory")
            .arg(self.data.path())
            .args(["--address", "127.0.0.1", "--port"])
            .arg(self.port.to_string())
            .args(["--configure-bucket", BUCKET, "--silent"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("starting s3rver");
        self.child = Some(child);
        let started = Instant::now();
        while !self.answers() {
            assert!(
                started.elapsed() < Duration::from_secs(30),
                "s3rver did not start on port {}",
                self.port
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Where the server keeps its objects, one file (or folder) per key: what it stores can be
    /// watched without a request.
    pub fn data_dir(&self) -> &std::path::Path {
        self.data.path()
    }

    /// Kills the server with SIGKILL (every connection drops, nothing is flushed).
    pub fn kill(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    fn answers(&self) -> bool {
        let Ok(mut stream) = TcpStream::connect(("127.0.0.1", self.port)) else {
            return false;
        };
        let _ = stream.set_read_timeout(Some(Duration::from_secs(2)));
        let request = "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
        if stream.write_all(request.as_bytes()).is_err() {
            return false;
        }
        let mut head = [0u8; 12];
        stream.read_exact(&mut head).is_ok() && head.starts_with(b"HTTP/1.1 200")
    }

    /// Blob settings for a fresh prefix of this server's bucket; requests give up quickly, so an
    /// outage shows within seconds.
    pub fn blobs(&self, test: &str) -> BlobsConfig {
        super::object_store::s3rver_blobs(
            &format!("http://127.0.0.1:{}", self.port),
            &format!("s3://{BUCKET}/{test}-{}", uuid::Uuid::new_v4().simple()),
        )
    }
}

impl Drop for OwnS3rver {
    fn drop(&mut self) {
        self.kill();
    }
}
