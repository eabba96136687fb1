//! The PostgreSQL server the store tests run against: `scripts/test_servers.sh` starts a
//! throwaway cluster (Debian's package) on 127.0.0.1 and exports `SEGSPLAT_TEST_POSTGRES_URL`.
//! Each test gets its own fresh database in it. Without the server a test skips with the
//! reason, except in CI (`CI=true`), where a missing server fails.
//!
//! `SEGSPLAT_TEST_BACKEND=postgres` makes [`super::test_config`] put every service test on a
//! fresh Postgres database: `scripts/test.sh` runs the job and store test files a second time
//! that way, so the same tests cover both backends.
//!
//! Tests that stop the server (connection loss) start a [`PrivateCluster`] of their own.

use std::path::PathBuf;
use std::process::Command;

use sqlx::Connection;

const URL_VARIABLE: &str = "SEGSPLAT_TEST_POSTGRES_URL";

fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|value| value == "true")
}

/// Whether the service tests should run on Postgres (`SEGSPLAT_TEST_BACKEND=postgres`).
pub fn backend_is_postgres() -> bool {
    std::env::var("SEGSPLAT_TEST_BACKEND").is_ok_and(|value| value == "postgres")
}

/// The test server's URL, or `None` (skip, with the reason printed) outside CI.
pub fn server_url(test: &str) -> Option<String> {
    match std::env::var(URL_VARIABLE) {
        Ok(url) => Some(url),
        Err(_) => {
            let reason = format!(
                "{URL_VARIABLE} is not set (scripts/test_servers.sh starts PostgreSQL and sets it)"
            );
            if in_ci() || backend_is_postgres() {
                panic!("{test} needs the PostgreSQL test server: {reason}");
            }
            eprintln!("skipping {test}: {reason}");
            None
        }
    }
}

/// A fresh, empty database on the test server; `None` (skip) when there is no server.
pub fn fresh_database(test: &str) -> Option<String> {
    let server = server_url(test)?;
    Some(create_database(&server))
}

/// The Postgres database that stands for `data_dir`'s SQLite file: created on first use and
/// remembered in the folder, so a test that restarts a service on the same data dir finds the
/// same database again.
pub fn database_for_data_dir(data_dir: &std::path::Path) -> String {
    let remembered = data_dir.join(".test-postgres-url");
    if let Ok(url) = std::fs::read_to_string(&remembered) {
        return url;
    }
    let server = server_url("test_config").expect("the PostgreSQL test server");
    let url = create_database(&server);
    std::fs::create_dir_all(data_dir).expect("creating the data dir");
    std::fs::write(&remembered, &url).expect("remembering the test database");
    url
}

/// Creates a uniquely named database on the server at `server_url` and returns its URL. Runs
/// its own runtime on a thread, so sync callers (`test_config`) and async tests can both use it.
pub fn create_database(server_url: &str) -> String {
    let server_url = server_url.to_string();
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("a runtime for creating the test database");
        runtime.block_on(async move {
            let name = format!("segsplat_test_{}", uuid::Uuid::new_v4().simple());
            let mut connection = sqlx::PgConnection::connect(&server_url)
                .await
                .expect("connecting to the PostgreSQL test server");
            sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
                .execute(&mut connection)
                .await
                .expect("creating a test database");
            connection.close().await.ok();
            let base = server_url
                .rsplit_once('/')
                .map_or(server_url.as_str(), |(base, _)| base);
            format!("{base}/{name}")
        })
    })
    .join()
    .expect("the thread creating the test database")
}

/// A PostgreSQL cluster of one test's own, which the test may stop and start again (to cut the
/// service off its database). Removed when dropped.
pub struct PrivateCluster {
    dir: PathBuf,
    bin: PathBuf,
    port: u16,
    as_postgres: bool,
}

impl PrivateCluster {
    /// Starts one, or `None` (skip) when the server binaries are not installed outside CI.
    pub fn start(test: &str) -> Option<PrivateCluster> {
        let bin = std::fs::read_dir("/usr/lib/postgresql")
            .ok()
            .into_iter()
            .flatten()
            .filter_map(Result::ok)
            .map(|entry| entry.path().join("bin"))
            .filter(|bin| bin.join("initdb").exists())
            .max();
        let Some(bin) = bin else {
            let reason = "no PostgreSQL server binaries under /usr/lib/postgresql \
                          (scripts/bootstrap.sh installs Debian's postgresql)";
            if in_ci() {
                panic!("{test} needs PostgreSQL: {reason}");
            }
            eprintln!("skipping {test}: {reason}");
            return None;
        };
        let dir = std::env::temp_dir().join(format!("segsplat-pg-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).expect("creating the cluster folder");
        // PostgreSQL refuses to run as root; the Debian package made a `postgres` user.
        let as_postgres = nix_is_root();
        if as_postgres {
            let status = Command::new("chown")
                .arg("postgres")
                .arg(&dir)
                .status()
                .expect("chown");
            assert!(status.success(), "chown postgres {}", dir.display());
        }
        let port = free_port();
        let cluster = PrivateCluster {
            dir,
            bin,
            port,
            as_postgres,
        };
        cluster.run(
            "initdb",
            &[
                "-D",
                &cluster.data().display().to_string(),
                "-A",
                "trust",
                "-U",
                "segsplat",
            ],
        );
        cluster.start_server();
        Some(cluster)
    }

    fn data(&self) -> PathBuf {
        self.dir.join("cluster")
    }

    /// A PostgreSQL tool, run as the `postgres` user when we are root.
    fn command(&self, program: &str) -> Command {
        let program = self.bin.join(program);
        if self.as_postgres {
            let mut command = Command::new("runuser");
            command.args(["-u", "postgres", "--"]).arg(&program);
            command
        } else {
            Command::new(&program)
        }
    }

    fn run(&self, program: &str, args: &[&str]) {
        let output = self
            .command(program)
            .args(args)
            .output()
            .expect("running a PostgreSQL tool");
        assert!(
            output.status.success(),
            "{program} {args:?} failed: {}{}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        );
    }

    /// Starts (or restarts) the server on the same port and data.
    pub fn start_server(&self) {
        let options = format!(
            "-c listen_addresses=127.0.0.1 -p {} -k {} -c fsync=off",
            self.port,
            self.dir.display()
        );
        self.run(
            "pg_ctl",
            &[
                "-D",
                &self.data().display().to_string(),
                "-l",
                &self.dir.join("server.log").display().to_string(),
                "-w",
                "-o",
                &options,
                "start",
            ],
        );
    }

    /// Stops the server at once, dropping every connection (as a crash or failover would).
    pub fn stop_server(&self) {
        self.run(
            "pg_ctl",
            &[
                "-D",
                &self.data().display().to_string(),
                "-m",
                "immediate",
                "-w",
                "stop",
            ],
        );
    }

    pub fn url(&self) -> String {
        format!("postgres://segsplat@127.0.0.1:{}/postgres", self.port)
    }
}

impl Drop for PrivateCluster {
    fn drop(&mut self) {
        let data = self.data().display().to_string();
        let _ = self
            .command("pg_ctl")
            .args(["-D", &data, "-m", "immediate", "stop"])
            .output();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn nix_is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|output| String::from_utf8_lossy(&output.stdout).trim() == "0")
}

/// A port nothing listens on now, on 127.0.0.1.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|addr| addr.port())
        .expect("a free port")
}
