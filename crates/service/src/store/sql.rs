//! One way to run a statement on either backend. The store writes each statement once, in the
//! SQL both SQLite and PostgreSQL accept, with `?` placeholders; on PostgreSQL they become
//! `$1, $2, ...`. Arguments and columns are limited to the few types the schema uses (text,
//! 64-bit integers, booleans, doubles, bytes), each of which both drivers encode natively, so
//! nothing is converted at run time. (sqlx's `Any` driver was the alternative; it refuses
//! SQLite's BOOLEAN columns and Postgres' 32-bit integers, which is how it came to this.)

use sqlx::postgres::PgRow;
use sqlx::sqlite::SqliteRow;
use sqlx::{ColumnIndex, PgPool, Postgres, Row, Sqlite, SqlitePool, Transaction};

/// The open connection pool, of whichever backend the config chose.
#[derive(Debug, Clone)]
pub(crate) enum Pool {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

/// An open transaction on either backend; dropped without `commit`, it rolls back.
pub(crate) enum Tx {
    Sqlite(Transaction<'static, Sqlite>),
    Postgres(Transaction<'static, Postgres>),
}

impl Pool {
    /// Begins a transaction. SQLite's takes the write lock at once (`BEGIN IMMEDIATE`, waiting
    /// out the busy timeout for it): a deferred one that reads and then writes fails at once with
    /// SQLITE_BUSY when another connection committed a write in between (WAL mode does not wait
    /// there), so two requests that meet, such as a scene deletion beside a worker finishing a
    /// job, would end in a 500.
    pub(crate) async fn begin(&self) -> Result<Tx, sqlx::Error> {
        Ok(match self {
            Pool::Sqlite(pool) => Tx::Sqlite(pool.begin_with("BEGIN IMMEDIATE").await?),
            Pool::Postgres(pool) => Tx::Postgres(pool.begin().await?),
        })
    }
}

impl Tx {
    pub(crate) async fn commit(self) -> Result<(), sqlx::Error> {
        match self {
            Tx::Sqlite(transaction) => transaction.commit().await,
            Tx::Postgres(transaction) => transaction.commit().await,
        }
    }
}

/// Where a statement runs: on a pooled connection, or inside a transaction.
pub(crate) enum On<'a> {
    Pool(&'a Pool),
    Tx(&'a mut Tx),
}

impl<'a> From<&'a Pool> for On<'a> {
    fn from(pool: &'a Pool) -> Self {
        On::Pool(pool)
    }
}

impl<'a> From<&'a mut Tx> for On<'a> {
    fn from(transaction: &'a mut Tx) -> Self {
        On::Tx(transaction)
    }
}

/// A bound argument.
#[derive(Debug, Clone)]
pub(crate) enum Arg {
    Text(Option<String>),
    Int(Option<i64>),
    Bool(bool),
    Float(f64),
    Bytes(Vec<u8>),
}

impl From<&str> for Arg {
    fn from(value: &str) -> Self {
        Arg::Text(Some(value.to_string()))
    }
}

impl From<String> for Arg {
    fn from(value: String) -> Self {
        Arg::Text(Some(value))
    }
}

impl From<&String> for Arg {
    fn from(value: &String) -> Self {
        Arg::Text(Some(value.clone()))
    }
}

impl From<Option<&str>> for Arg {
    fn from(value: Option<&str>) -> Self {
        Arg::Text(value.map(str::to_string))
    }
}

impl From<Option<String>> for Arg {
    fn from(value: Option<String>) -> Self {
        Arg::Text(value)
    }
}

impl From<&Option<String>> for Arg {
    fn from(value: &Option<String>) -> Self {
        Arg::Text(value.clone())
    }
}

impl From<i64> for Arg {
    fn from(value: i64) -> Self {
        Arg::Int(Some(value))
    }
}

impl From<Option<i64>> for Arg {
    fn from(value: Option<i64>) -> Self {
        Arg::Int(value)
    }
}

impl From<bool> for Arg {
    fn from(value: bool) -> Self {
        Arg::Bool(value)
    }
}

impl From<f64> for Arg {
    fn from(value: f64) -> Self {
        Arg::Float(value)
    }
}

impl From<f32> for Arg {
    fn from(value: f32) -> Self {
        Arg::Float(f64::from(value))
    }
}

impl From<Vec<u8>> for Arg {
    fn from(value: Vec<u8>) -> Self {
        Arg::Bytes(value)
    }
}

/// A statement and its arguments, in order.
#[derive(Debug, Clone)]
pub(crate) struct Statement {
    sql: String,
    args: Vec<Arg>,
}

pub(crate) fn query(sql: impl Into<String>) -> Statement {
    Statement {
        sql: sql.into(),
        args: Vec::new(),
    }
}

/// Binds every argument onto a fresh sqlx query; expanded once per backend.
macro_rules! bound {
    ($sql:expr, $args:expr) => {{
        let mut query = sqlx::query(sqlx::AssertSqlSafe($sql));
        for arg in $args {
            query = match arg {
                Arg::Text(value) => query.bind(value),
                Arg::Int(value) => query.bind(value),
                Arg::Bool(value) => query.bind(value),
                Arg::Float(value) => query.bind(value),
                Arg::Bytes(value) => query.bind(value),
            };
        }
        query
    }};
}

/// Runs `$method` on whichever backend `$on` is, wrapping rows with `$wrap`.
macro_rules! run {
    ($statement:expr, $on:expr, $method:ident, |$result:ident| $wrap:expr) => {{
        let Statement { sql, args } = $statement;
        match $on {
            On::Pool(Pool::Sqlite(pool)) => {
                let $result = bound!(sql, args).$method(pool).await?;
                $wrap
            }
            On::Pool(Pool::Postgres(pool)) => {
                let $result = bound!(numbered(&sql), args).$method(pool).await?;
                $wrap
            }
            On::Tx(Tx::Sqlite(transaction)) => {
                let $result = bound!(sql, args).$method(&mut **transaction).await?;
                $wrap
            }
            On::Tx(Tx::Postgres(transaction)) => {
                let $result = bound!(numbered(&sql), args)
                    .$method(&mut **transaction)
                    .await?;
                $wrap
            }
        }
    }};
}

impl Statement {
    pub(crate) fn bind(mut self, value: impl Into<Arg>) -> Self {
        self.args.push(value.into());
        self
    }

    pub(crate) async fn fetch_all<'a>(
        self,
        on: impl Into<On<'a>>,
    ) -> Result<Vec<DbRow>, sqlx::Error> {
        Ok(run!(self, on.into(), fetch_all, |rows| rows
            .into_iter()
            .map(DbRow::from)
            .collect()))
    }

    pub(crate) async fn fetch_optional<'a>(
        self,
        on: impl Into<On<'a>>,
    ) -> Result<Option<DbRow>, sqlx::Error> {
        Ok(run!(self, on.into(), fetch_optional, |row| row.map(DbRow::from)))
    }

    pub(crate) async fn fetch_one<'a>(self, on: impl Into<On<'a>>) -> Result<DbRow, sqlx::Error> {
        Ok(run!(self, on.into(), fetch_one, |row| DbRow::from(row)))
    }

    /// Runs the statement; returns the rows it changed.
    pub(crate) async fn execute<'a>(self, on: impl Into<On<'a>>) -> Result<u64, sqlx::Error> {
        Ok(run!(self, on.into(), execute, |done| done.rows_affected()))
    }
}

/// A result row of either backend.
#[derive(Debug)]
pub(crate) enum DbRow {
    Sqlite(SqliteRow),
    Postgres(PgRow),
}

impl From<SqliteRow> for DbRow {
    fn from(row: SqliteRow) -> Self {
        DbRow::Sqlite(row)
    }
}

impl From<PgRow> for DbRow {
    fn from(row: PgRow) -> Self {
        DbRow::Postgres(row)
    }
}

impl DbRow {
    /// The column by name or position, as `T`.
    pub(crate) fn try_get<T: Column, I>(&self, index: I) -> Result<T, sqlx::Error>
    where
        I: ColumnIndex<SqliteRow> + ColumnIndex<PgRow>,
    {
        match self {
            DbRow::Sqlite(row) => T::from_sqlite(row, index),
            DbRow::Postgres(row) => T::from_postgres(row, index),
        }
    }
}

/// A Rust type both drivers decode a column into.
pub(crate) trait Column: Sized {
    fn from_sqlite<I: ColumnIndex<SqliteRow>>(
        row: &SqliteRow,
        index: I,
    ) -> Result<Self, sqlx::Error>;
    fn from_postgres<I: ColumnIndex<PgRow>>(row: &PgRow, index: I) -> Result<Self, sqlx::Error>;
}

macro_rules! columns {
    ($($type:ty),* $(,)?) => {$(
        impl Column for $type {
            fn from_sqlite<I: ColumnIndex<SqliteRow>>(
                row: &SqliteRow,
                index: I,
            ) -> Result<Self, sqlx::Error> {
                row.try_get(index)
            }
            fn from_postgres<I: ColumnIndex<PgRow>>(
                row: &PgRow,
                index: I,
            ) -> Result<Self, sqlx::Error> {
                row.try_get(index)
            }
        }
    )*};
}

columns!(
    String,
    Option<String>,
    i64,
    Option<i64>,
    bool,
    Option<bool>,
    f64,
    Vec<u8>,
);

/// `?` placeholders as PostgreSQL's `$1, $2, ...`, leaving quoted literals and identifiers
/// alone.
pub(crate) fn numbered(sql: &str) -> String {
    let mut out = String::with_capacity(sql.len() + 16);
    let mut quote: Option<char> = None;
    let mut next = 1;
    for character in sql.chars() {
        match (quote, character) {
            (None, '\'' | '"') => {
                quote = Some(character);
                out.push(character);
            }
            (Some(open), _) if character == open => {
                quote = None;
                out.push(character);
            }
            (None, '?') => {
                out.push('$');
                out.push_str(&next.to_string());
                next += 1;
            }
            _ => out.push(character),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::{Pool, Tx, numbered};
    use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions};
    use std::time::Duration;

    /// A transaction that reads, then writes after another connection has written, commits:
    /// the other writer waits for it instead of the transaction failing with SQLITE_BUSY (which
    /// a deferred `BEGIN` gets in WAL mode, the busy timeout notwithstanding).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_sqlite_transaction_reading_then_writing_outlasts_another_writer() {
        let dir = tempfile::tempdir().unwrap();
        let options = SqliteConnectOptions::new()
            .filename(dir.path().join("db.sqlite"))
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .busy_timeout(Duration::from_secs(10));
        let sqlite = SqlitePoolOptions::new()
            .max_connections(2)
            .connect_with(options)
            .await
            .unwrap();
        sqlx::query("CREATE TABLE t (x INTEGER)")
            .execute(&sqlite)
            .await
            .unwrap();
        let pool = Pool::Sqlite(sqlite.clone());
        let Tx::Sqlite(mut transaction) = pool.begin().await.unwrap() else {
            unreachable!("a SQLite pool begins SQLite transactions")
        };
        sqlx::query("SELECT COUNT(*) FROM t")
            .fetch_one(&mut *transaction)
            .await
            .unwrap();
        let other = tokio::spawn(async move {
            sqlx::query("INSERT INTO t VALUES (2)")
                .execute(&sqlite)
                .await
        });
        tokio::time::sleep(Duration::from_millis(200)).await;
        sqlx::query("INSERT INTO t VALUES (1)")
            .execute(&mut *transaction)
            .await
            .unwrap();
        transaction.commit().await.unwrap();
        other.await.unwrap().unwrap();
    }

    #[test]
    fn placeholders_are_numbered_outside_quotes() {
        assert_eq!(
            numbered("SELECT ? || 'a?b' || \"c?\" FROM t WHERE x = ? AND y IN (?, ?)"),
            "SELECT $1 || 'a?b' || \"c?\" FROM t WHERE x = $2 AND y IN ($3, $4)"
        );
        assert_eq!(numbered("it''s ?"), "it''s $1");
        assert_eq!(numbered("'it''s ?' ?"), "'it''s ?' $1");
    }
}
