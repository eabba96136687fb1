//! Opening the database the config names, SQLite (WAL, busy timeout, foreign keys) or
//! PostgreSQL, and applying that backend's embedded migrations (`crates/service/migrations/`).

use std::borrow::Cow;
use std::path::Path;
use std::str::FromStr;
use std::time::{Duration, Instant};

use sqlx::SqlSafeStr;
use sqlx::migrate::{Migration, MigrationType, Migrator};
use sqlx::postgres::{PgConnectOptions, PgPoolOptions};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

use super::StoreError;
use super::sql::{Pool, Tx};
use crate::config::{Config, DatabaseConfig};

/// One migration per schema version, the same versions and descriptions on both backends; a
/// test applies both sets and compares the resulting tables and columns.
type Migrations = &'static [(i64, &'static str, &'static str)];

/// Compiled into the binary, so a deployed `segsplat` needs no files beside it.
const SQLITE_MIGRATIONS: Migrations = &[
    (
        1,
        "initial",
        include_str!("../../migrations/sqlite/0001_initial.sql"),
    ),
    (
        2,
        "lease expiries",
        include_str!("../../migrations/sqlite/0002_lease_expiries.sql"),
    ),
    (
        3,
        "tenants",
        include_str!("../../migrations/sqlite/0003_tenants.sql"),
    ),
    (
        4,
        "workers",
        include_str!("../../migrations/sqlite/0004_workers.sql"),
    ),
    (
        5,
        "blob deletions",
        include_str!("../../migrations/sqlite/0005_blob_deletions.sql"),
    ),
    (
        6,
        "job settings",
        include_str!("../../migrations/sqlite/0006_job_settings.sql"),
    ),
];

const POSTGRES_MIGRATIONS: Migrations = &[
    (
        1,
        "initial",
        include_str!("../../migrations/postgres/0001_initial.sql"),
    ),
    (
        2,
        "lease expiries",
        include_str!("../../migrations/postgres/0002_lease_expiries.sql"),
    ),
    (
        3,
        "tenants",
        include_str!("../../migrations/postgres/0003_tenants.sql"),
    ),
    (
        4,
        "workers",
        include_str!("../../migrations/postgres/0004_workers.sql"),
    ),
    (
        5,
        "blob deletions",
        include_str!("../../migrations/postgres/0005_blob_deletions.sql"),
    ),
    (
        6,
        "job settings",
        include_str!("../../migrations/postgres/0006_job_settings.sql"),
    ),
];

/// How long a SQLite writer waits for another writer's lock before failing.
const BUSY_TIMEOUT: Duration = Duration::from_secs(10);

/// Which engine holds the state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    Sqlite,
    Postgres,
}

impl Backend {
    pub fn name(self) -> &'static str {
        match self {
            Backend::Sqlite => "sqlite",
            Backend::Postgres => "postgres",
        }
    }
}

#[derive(Debug, Clone)]
pub struct Database {
    pool: Pool,
}

impl Database {
    /// The database `config` names: `database.url` when set, else `{data_dir}/segsplat.db`.
    pub async fn connect(config: &Config) -> Result<Self, StoreError> {
        match &config.database.url {
            Some(url) => Self::open_postgres(url, &config.database).await,
            None => Self::open(&config.database_path()).await,
        }
    }

    /// Opens (creating if needed) the SQLite file and brings its schema up to date.
    pub async fn open(path: &Path) -> Result<Self, StoreError> {
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|source| StoreError::CreateDir {
                path: parent.display().to_string(),
                source,
            })?;
        }
        let options = SqliteConnectOptions::from_str("sqlite:")?
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Normal)
            .busy_timeout(BUSY_TIMEOUT)
            .foreign_keys(true);
        let pool = SqlitePoolOptions::new()
            .max_connections(8)
            .connect_with(options)
            .await?;
        migrator(SQLITE_MIGRATIONS).run(&pool).await?;
        Ok(Self {
            pool: Pool::Sqlite(pool),
        })
    }

    /// Connects to PostgreSQL at `url`, retrying for `connect_retry_secs` while the server is
    /// unreachable (it may be starting beside us), and brings its schema up to date. Migrations
    /// hold Postgres' advisory lock, so processes starting together apply them once.
    pub async fn open_postgres(url: &str, config: &DatabaseConfig) -> Result<Self, StoreError> {
        let options = PgConnectOptions::from_str(url)?;
        let pool = PgPoolOptions::new()
            .max_connections(config.max_connections)
            .acquire_timeout(Duration::from_secs(config.acquire_timeout_secs))
            .connect_lazy_with(options);
        let deadline = Instant::now() + Duration::from_secs(config.connect_retry_secs);
        loop {
            match migrator(POSTGRES_MIGRATIONS).run(&pool).await {
                Ok(()) => break,
                Err(error) => {
                    let error = StoreError::from(error);
                    if !error.is_unavailable() || Instant::now() >= deadline {
                        return Err(error);
                    }
                    tracing::warn!(%error, "PostgreSQL not reachable yet; retrying");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        }
        Ok(Self {
            pool: Pool::Postgres(pool),
        })
    }

    pub fn backend(&self) -> Backend {
        match self.pool {
            Pool::Sqlite(_) => Backend::Sqlite,
            Pool::Postgres(_) => Backend::Postgres,
        }
    }

    pub(crate) fn sql(&self) -> &Pool {
        &self.pool
    }

    pub(crate) fn postgres_pool(&self) -> Option<&sqlx::PgPool> {
        match &self.pool {
            Pool::Postgres(pool) => Some(pool),
            Pool::Sqlite(_) => None,
        }
    }

    pub(crate) async fn begin(&self) -> Result<Tx, StoreError> {
        Ok(self.pool.begin().await?)
    }

    /// A trivial round trip, for readiness checks.
    pub async fn ping(&self) -> Result<(), StoreError> {
        super::sql::query("SELECT 1").execute(self.sql()).await?;
        Ok(())
    }

    pub async fn close(&self) {
        match &self.pool {
            Pool::Sqlite(pool) => pool.close().await,
            Pool::Postgres(pool) => pool.close().await,
        }
    }
}

fn migrator(migrations: Migrations) -> Migrator {
    Migrator::with_migrations(
        migrations
            .iter()
            .map(|(version, description, sql)| {
                Migration::new(
                    *version,
                    Cow::Borrowed(*description),
                    MigrationType::Simple,
                    sql.into_sql_str(),
                    false,
                )
            })
            .collect(),
    )
}
