//! The one typed service configuration, layered: defaults < TOML file < `SEGSPLAT_*` environment
//! < command-line flags, then validated once at start so a bad value fails loudly, naming its key.
//!
//! Environment variables map onto keys by lower-casing the name after `SEGSPLAT_` and reading `__`
//! as a nesting step: `SEGSPLAT_HTTP_ADDR` is `http_addr`, `SEGSPLAT_JOBS__LEASE_SECS` is
//! `jobs.lease_secs`. Values are read as TOML values when they parse as one (`5`, `true`,
//! `["a","b"]`) and as plain strings otherwise. Variables whose first segment is not a top-level
//! key (e.g. `SEGSPLAT_SKIP_GPU_TESTS`) belong to other tools and are ignored.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use segsplat_gpu::AdapterFilter;
use segsplat_scene::VideoFrameOptions;
pub use segsplat_vision::models::ModelsConfig;

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read config file {path}: {source}")]
    Read {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("config file {path}: {message}")]
    Parse { path: String, message: String },
    #[error("environment variable {variable}: {message}")]
    Env { variable: String, message: String },
    #[error("configuration: {message}")]
    Merge { message: String },
    #[error("{key}: {reason}")]
    Invalid { key: String, reason: String },
}

/// Environment variable prefix for configuration keys.
pub const ENV_PREFIX: &str = "SEGSPLAT_";

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Everything the service keeps: the SQLite database, blobs and temporary uploads.
    pub data_dir: PathBuf,
    pub http_addr: SocketAddr,
    pub grpc_addr: SocketAddr,
    pub auth: AuthConfig,
    pub limits: LimitsConfig,
    pub scene: SceneConfig,
    pub jobs: JobsConfig,
    pub workers: WorkersConfig,
    pub models: ModelsConfig,
    pub query: QueryConfig,
    pub storage: StorageConfig,
    pub database: DatabaseConfig,
    pub blobs: BlobsConfig,
    pub log: LogConfig,
    pub console: ConsoleConfig,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            data_dir: PathBuf::from("./data"),
            http_addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            grpc_addr: SocketAddr::from(([127, 0, 0, 1], 50051)),
            auth: AuthConfig::default(),
            limits: LimitsConfig::default(),
            scene: SceneConfig::default(),
            jobs: JobsConfig::default(),
            workers: WorkersConfig::default(),
            models: ModelsConfig::default(),
            query: QueryConfig::default(),
            storage: StorageConfig::default(),
            database: DatabaseConfig::default(),
            blobs: BlobsConfig::default(),
            log: LogConfig::default(),
            console: ConsoleConfig::default(),
        }
    }
}

/// Reclaiming leftovers of killed processes (`jobs::temp_sweep`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StorageConfig {
    /// A temporary file whose writer cannot be told dead (another host, an old name) is removed
    /// once untouched this long.
    pub temp_max_age_secs: u64,
    /// How often the sweep runs after the one at start.
    pub sweep_interval_secs: u64,
}

impl Default for StorageConfig {
    fn default() -> Self {
        Self {
            temp_max_age_secs: 86_400,
            sweep_interval_secs: 600,
        }
    }
}

/// Which SQL database holds the service's state: `{data_dir}/segsplat.db` (SQLite) by default,
/// or a PostgreSQL server shared by API and worker processes on many hosts.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatabaseConfig {
    /// `postgres://user:password@host:5432/dbname` (any libpq-style URL sqlx accepts); unset
    /// for the embedded SQLite file.
    pub url: Option<String>,
    /// Connections this process keeps open at most (PostgreSQL only).
    pub max_connections: u32,
    /// How long a request waits for a connection before it is answered 503 `unavailable`.
    pub acquire_timeout_secs: u64,
    /// How long a starting process keeps retrying an unreachable server before it gives up,
    /// so API and workers may start before the database in compose or Kubernetes.
    pub connect_retry_secs: u64,
}

impl Default for DatabaseConfig {
    fn default() -> Self {
        Self {
            url: None,
            max_connections: 16,
            acquire_timeout_secs: 5,
            connect_retry_secs: 60,
        }
    }
}

/// Where blobs (scene files, checkpoints, trained outputs) live: `{data_dir}/blobs` by default,
/// or an S3-compatible bucket. Unset S3 settings come from the standard `AWS_*` environment
/// variables (`AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_REGION`, `AWS_ENDPOINT`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BlobsConfig {
    /// `s3://bucket` or `s3://bucket/prefix`; unset for the local directory.
    pub url: Option<String>,
    /// The S3 endpoint of a self-hosted server (MinIO, Ceph, s3rver), e.g.
    /// `http://127.0.0.1:9000`; requests are then path-style.
    pub endpoint: Option<String>,
    pub region: Option<String>,
    pub access_key_id: Option<String>,
    pub secret_access_key: Option<String>,
    /// Allow `http://` endpoints (a server on the same host or network).
    pub allow_http: bool,
    /// One request's limit, retries included; a store that does not answer within it is
    /// reported unavailable (503) rather than waited for.
    pub request_timeout_secs: f64,
    pub max_retries: u32,
    /// Workers keep local copies of scenes from an object store under `{data_dir}/cache/scenes`;
    /// past this size the least recently used copies not in use are removed.
    pub worker_cache_mib: u64,
}

impl Default for BlobsConfig {
    fn default() -> Self {
        Self {
            url: None,
            endpoint: None,
            region: None,
            access_key_id: None,
            secret_access_key: None,
            allow_http: false,
            request_timeout_secs: 30.0,
            max_retries: 3,
            worker_cache_mib: 20 * 1024,
        }
    }
}

/// Bearer tokens and the tenants they act for (`docs/service.md`, "Tenants"). With neither
/// list set, authentication is off and every caller sees everything.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AuthConfig {
    /// Plain tokens: each acts for the `default` tenant, which also owns everything stored
    /// before tenants existed (so a service upgraded with only these behaves as before).
    pub tokens: Vec<String>,
    /// Tokens with a tenant and an admin flag: `[[auth.token]]` tables.
    pub token: Vec<TenantToken>,
}

impl AuthConfig {
    pub fn enabled(&self) -> bool {
        !self.tokens.is_empty() || !self.token.is_empty()
    }
}

/// One `[[auth.token]]`: the token, the tenant it acts for, and whether it sees every tenant.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TenantToken {
    pub token: String,
    /// Owner of what this token creates; required unless `admin` (then `default`).
    #[serde(default)]
    pub tenant: Option<String>,
    /// Sees and touches every tenant's scenes and jobs.
    #[serde(default)]
    pub admin: bool,
}

impl TenantToken {
    pub fn tenant_name(&self) -> &str {
        self.tenant
            .as_deref()
            .unwrap_or(crate::store::DEFAULT_TENANT)
    }
}

/// Tenant names: short, and safe in logs and file names.
fn valid_tenant_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name
            .bytes()
            .all(|byte| byte.is_ascii_alphanumeric() || b"-_.".contains(&byte))
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LimitsConfig {
    /// Largest accepted upload body (the archive as sent).
    pub max_upload_bytes: u64,
    /// Largest total size an archive may unpack to (zip bombs).
    pub max_unpacked_bytes: u64,
    /// Most files an archive may hold.
    pub max_files: u64,
    /// Most pixels one uploaded frame image may have (read from its header before decoding).
    pub max_image_pixels: u64,
    /// Most pixels an upload's frame images may have together.
    pub max_total_pixels: u64,
}

impl Default for LimitsConfig {
    fn default() -> Self {
        Self {
            max_upload_bytes: 2 << 30,
            max_unpacked_bytes: 8 << 30,
            max_files: 100_000,
            max_image_pixels: 100_000_000,
            max_total_pixels: 20_000_000_000,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SceneConfig {
    /// Background composited under RGBA (Blender) images, linear RGB in 0..1.
    pub background: [f32; 3],
    /// How uploaded Neu3D videos become frame images (frame step, count, size, ffmpeg path).
    pub video_frames: VideoFrameOptions,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            background: [1.0, 1.0, 1.0],
            video_frames: VideoFrameOptions::default(),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JobsConfig {
    /// How long a claimed job stays leased without a heartbeat before it is re-queued.
    pub lease_secs: f64,
    /// How often a worker renews its lease; well under `lease_secs`.
    pub heartbeat_secs: f64,
    /// Claims per job before it fails for good, counting those that ended in an error and lease
    /// expiries without a new checkpoint.
    pub max_attempts: u32,
    /// Lease expiries after which the job had saved a newer checkpoint (the process died while
    /// the job progressed) before it fails for good; they do not count against `max_attempts`.
    pub max_lease_expiries: u32,
    /// How often an idle worker looks for work (it is also woken when a job is queued here).
    pub poll_interval_ms: u64,
    /// Largest `steps` a job config may ask for.
    pub max_steps: u64,
    /// Largest `max_gaussians`, `random_init_count` and `background_shell` a job config may ask
    /// for.
    pub max_gaussians: u64,
    /// Keep a succeeded job's checkpoints (off: deleted once it succeeds; they only serve a
    /// resume and can be hundreds of MB).
    pub keep_final_checkpoint: bool,
}

impl Default for JobsConfig {
    fn default() -> Self {
        Self {
            lease_secs: 60.0,
            heartbeat_secs: 10.0,
            max_attempts: 3,
            max_lease_expiries: 10,
            poll_interval_ms: 1000,
            keep_final_checkpoint: false,
            max_steps: 1_000_000,
            max_gaussians: 10_000_000,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorkersConfig {
    /// Run job workers inside `serve` (off = API only; workers run as `segsplat worker`).
    pub enabled: bool,
    /// Concurrent jobs per GPU adapter.
    pub slots_per_adapter: u32,
    /// Which adapters workers use.
    pub adapters: AdapterFilter,
    /// Workers without a GPU, for job kinds that do not need one.
    pub cpu_slots: u32,
    /// A stable name for this process's workers (lease owners are `{instance_id}/{slot}`). A
    /// process starting under it re-queues that name's running jobs at once instead of waiting
    /// for their leases to run out, so it must be unique among processes sharing a data dir.
    /// Unset: `{host}-pid{pid}-{random}`, and a stopped process's jobs on the same host are
    /// re-queued as soon as it is seen to be gone.
    pub instance_id: Option<String>,
    /// Where a `segsplat worker` process serves `/healthz`, `/readyz` and `/metrics` (an API
    /// process serves them on `http_addr`). Its own port, so a worker beside `serve` on one
    /// host does not collide with it.
    pub ops_addr: SocketAddr,
}

impl Default for WorkersConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            slots_per_adapter: 1,
            adapters: AdapterFilter::default(),
            cpu_slots: 0,
            instance_id: None,
            ops_addr: SocketAddr::from(([127, 0, 0, 1], 8081)),
        }
    }
}

/// Serving queries and masks from trained scenes.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QueryConfig {
    /// GPU memory the mask cache may fill with trained scenes' Gaussians before it drops the
    /// least recently used (a scene larger than this is still served, alone).
    pub cache_budget_mib: u64,
    /// Longest side of a rendered mask; larger requests are refused.
    pub max_mask_side: u32,
}

impl Default for QueryConfig {
    fn default() -> Self {
        Self {
            cache_budget_mib: 2048,
            max_mask_side: crate::serving::DEFAULT_MAX_MASK_SIDE,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    #[default]
    Human,
    Json,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LogConfig {
    pub format: LogFormat,
    /// A `tracing` filter directive, e.g. `info` or `segsplat=debug,info`.
    pub level: String,
}

impl Default for LogConfig {
    fn default() -> Self {
        Self {
            format: LogFormat::Human,
            level: "info".to_string(),
        }
    }
}

/// The web console served at `/` (docs/console.md).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ConsoleConfig {
    /// The operators' Grafana dashboard, linked from the console's status page when set
    /// (e.g. `http://grafana.internal:3000/d/segsplat`).
    pub grafana_url: Option<String>,
}

/// Values given on the command line; they win over file and environment.
#[derive(Debug, Clone, Default)]
pub struct ConfigOverrides {
    pub data_dir: Option<PathBuf>,
    pub http_addr: Option<SocketAddr>,
    pub grpc_addr: Option<SocketAddr>,
    pub database_url: Option<String>,
    /// `serve --api-only`: no workers in this process (`workers.enabled = false`).
    pub api_only: bool,
}

impl Config {
    /// Layers defaults, the optional TOML file, the given `SEGSPLAT_*` variables and the flags,
    /// then validates.
    pub fn load(
        file: Option<&Path>,
        environment: impl IntoIterator<Item = (String, String)>,
        overrides: &ConfigOverrides,
    ) -> Result<Config, ConfigError> {
        let mut layered =
            toml::Table::try_from(Config::default()).map_err(|error| ConfigError::Merge {
                message: error.to_string(),
            })?;
        if let Some(path) = file {
            let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
                path: path.display().to_string(),
                source,
            })?;
            let from_file: toml::Table =
                toml::from_str(&text).map_err(|error| ConfigError::Parse {
                    path: path.display().to_string(),
                    message: error.to_string(),
                })?;
            merge_tables(&mut layered, from_file);
        }
        let top_level_keys: Vec<String> = layered.keys().cloned().collect();
        for (variable, value) in environment {
            let Some(key_path) = variable.strip_prefix(ENV_PREFIX) else {
                continue;
            };
            let segments: Vec<String> = key_path.split("__").map(str::to_lowercase).collect();
            if !top_level_keys.contains(&segments[0]) {
                continue;
            }
            insert_env_value(&mut layered, &segments, &value).map_err(|message| {
                ConfigError::Env {
                    variable: variable.clone(),
                    message,
                }
            })?;
        }
        let mut config: Config =
            layered
                .try_into()
                .map_err(|error: toml::de::Error| ConfigError::Merge {
                    message: error.to_string(),
                })?;
        if let Some(data_dir) = &overrides.data_dir {
            config.data_dir = data_dir.clone();
        }
        if let Some(addr) = overrides.http_addr {
            config.http_addr = addr;
        }
        if let Some(addr) = overrides.grpc_addr {
            config.grpc_addr = addr;
        }
        if let Some(url) = &overrides.database_url {
            config.database.url = Some(url.clone());
        }
        if overrides.api_only {
            config.workers.enabled = false;
        }
        config.validate()?;
        Ok(config)
    }

    /// Checks every value that deserialization alone cannot, naming the key and the reason.
    /// `[[auth.token]]`: a token, a valid tenant (required for non-admins), and no token
    /// listed twice (it could not say which tenant it acts for).
    fn validate_tenant_tokens(&self) -> Result<(), ConfigError> {
        let invalid = |index: usize, reason: String| {
            Err(ConfigError::Invalid {
                key: format!("auth.token[{index}]"),
                reason,
            })
        };
        let mut seen: std::collections::HashSet<&str> =
            self.auth.tokens.iter().map(|token| token.trim()).collect();
        for (index, entry) in self.auth.token.iter().enumerate() {
            if entry.token.trim().is_empty() {
                return invalid(index, "token must not be empty".to_string());
            }
            if entry.tenant.is_none() && !entry.admin {
                return invalid(index, "tenant is required unless admin = true".to_string());
            }
            if !valid_tenant_name(entry.tenant_name()) {
                return invalid(
                    index,
                    "tenant must be 1 to 64 characters of A-Z, a-z, 0-9, '-', '_' or '.'"
                        .to_string(),
                );
            }
            if !seen.insert(entry.token.trim()) {
                return invalid(
                    index,
                    "this token is listed twice in auth.tokens / auth.token".to_string(),
                );
            }
        }
        Ok(())
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        fn invalid(key: &str, reason: &str) -> Result<(), ConfigError> {
            Err(ConfigError::Invalid {
                key: key.to_string(),
                reason: reason.to_string(),
            })
        }
        if self.data_dir.as_os_str().is_empty() {
            return invalid("data_dir", "must not be empty");
        }
        if self.auth.tokens.iter().any(|token| token.trim().is_empty()) {
            return invalid("auth.tokens", "tokens must not be empty strings");
        }
        self.validate_tenant_tokens()?;
        if self.limits.max_upload_bytes == 0 {
            return invalid("limits.max_upload_bytes", "must be > 0");
        }
        if self.limits.max_unpacked_bytes == 0 {
            return invalid("limits.max_unpacked_bytes", "must be > 0");
        }
        if self.limits.max_files == 0 {
            return invalid("limits.max_files", "must be > 0");
        }
        if self
            .scene
            .background
            .iter()
            .any(|channel| !(0.0..=1.0).contains(channel))
        {
            return invalid("scene.background", "each channel must be within 0..1");
        }
        let video_frames = &self.scene.video_frames;
        if video_frames.frame_step == 0 {
            return invalid("scene.video_frames.frame_step", "must be > 0");
        }
        if video_frames.max_frames == Some(0) || video_frames.max_side == Some(0) {
            return invalid(
                "scene.video_frames",
                "max_frames and max_side must be > 0 when set",
            );
        }
        if self.query.max_mask_side == 0 {
            return invalid("query.max_mask_side", "must be > 0");
        }
        if let Some(url) = &self.blobs.url {
            let bucket = url.strip_prefix("s3://").map(|rest| rest.split('/').next());
            if !matches!(bucket, Some(Some(name)) if !name.is_empty()) {
                return invalid(
                    "blobs.url",
                    "must be s3://bucket or s3://bucket/prefix (unset for the local directory)",
                );
            }
        }
        if !(self.blobs.request_timeout_secs.is_finite() && self.blobs.request_timeout_secs > 0.0) {
            return invalid("blobs.request_timeout_secs", "must be > 0");
        }
        if !(self.jobs.lease_secs.is_finite() && self.jobs.lease_secs > 0.0) {
            return invalid("jobs.lease_secs", "must be > 0");
        }
        if !(self.jobs.heartbeat_secs.is_finite() && self.jobs.heartbeat_secs > 0.0) {
            return invalid("jobs.heartbeat_secs", "must be > 0");
        }
        if self.jobs.heartbeat_secs >= self.jobs.lease_secs {
            return invalid(
                "jobs.heartbeat_secs",
                "must be less than jobs.lease_secs, or leases expire between heartbeats",
            );
        }
        if let Some(url) = &self.database.url
            && !(url.starts_with("postgres://") || url.starts_with("postgresql://"))
        {
            return invalid(
                "database.url",
                "must start with postgres:// or postgresql:// (unset for the SQLite file)",
            );
        }
        if self.database.max_connections == 0 {
            return invalid("database.max_connections", "must be >= 1");
        }
        if self.database.acquire_timeout_secs == 0 {
            return invalid("database.acquire_timeout_secs", "must be >= 1");
        }
        if self.jobs.max_attempts == 0 {
            return invalid("jobs.max_attempts", "must be >= 1");
        }
        if self.storage.sweep_interval_secs == 0 {
            return invalid("storage.sweep_interval_secs", "must be >= 1");
        }
        if self.jobs.max_lease_expiries == 0 {
            return invalid("jobs.max_lease_expiries", "must be >= 1");
        }
        if self.jobs.poll_interval_ms == 0 {
            return invalid("jobs.poll_interval_ms", "must be > 0");
        }
        if let Some(instance_id) = &self.workers.instance_id
            && (instance_id.trim().is_empty() || instance_id.contains('/'))
        {
            return invalid("workers.instance_id", "must be non-empty and without '/'");
        }
        if self.workers.slots_per_adapter == 0 {
            return invalid("workers.slots_per_adapter", "must be >= 1");
        }
        if let Some(dir) = &self.models.dir
            && dir.as_os_str().is_empty()
        {
            return invalid(
                "models.dir",
                "must not be empty (leave it unset for no models)",
            );
        }
        if let Some(library) = &self.models.ort_library
            && library.as_os_str().is_empty()
        {
            return invalid(
                "models.ort_library",
                "must not be empty (leave it unset to search)",
            );
        }
        const MAX_THREADS: usize = 1024;
        if self.models.intra_threads > MAX_THREADS {
            return invalid(
                "models.intra_threads",
                "must be <= 1024 (0 = ONNX Runtime's default)",
            );
        }
        if self.models.inter_threads > MAX_THREADS {
            return invalid(
                "models.inter_threads",
                "must be <= 1024 (0 = ONNX Runtime's default)",
            );
        }
        if let Err(error) = tracing_subscriber::EnvFilter::try_new(&self.log.level) {
            return invalid("log.level", &format!("not a tracing filter: {error}"));
        }
        Ok(())
    }

    pub fn database_path(&self) -> PathBuf {
        self.data_dir.join("segsplat.db")
    }

    pub fn blob_dir(&self) -> PathBuf {
        self.data_dir.join("blobs")
    }

    /// Workers' local copies of scenes whose files are in an object store.
    pub fn scene_cache_dir(&self) -> PathBuf {
        self.data_dir.join("cache").join("scenes")
    }

    /// Uploads and unpacking happen here, on the same filesystem as the blobs.
    pub fn scratch_dir(&self) -> PathBuf {
        self.data_dir.join("tmp")
    }
}

fn merge_tables(base: &mut toml::Table, overlay: toml::Table) {
    for (key, value) in overlay {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(base_table)), toml::Value::Table(overlay_table)) => {
                merge_tables(base_table, overlay_table);
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

fn insert_env_value(table: &mut toml::Table, segments: &[String], raw: &str) -> Result<(), String> {
    let Some((last, parents)) = segments.split_last() else {
        return Err("empty key".to_string());
    };
    let mut current = table;
    for segment in parents {
        let entry = current
            .entry(segment.clone())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        current = match entry {
            toml::Value::Table(inner) => inner,
            _ => return Err(format!("{segment} is not a section")),
        };
    }
    current.insert(last.clone(), parse_env_value(raw));
    Ok(())
}

/// A TOML value when the text is one (`5`, `true`, `["a"]`), the text as a string otherwise.
fn parse_env_value(raw: &str) -> toml::Value {
    let document = format!("value = {raw}");
    match toml::from_str::<toml::Table>(&document) {
        Ok(mut parsed) => parsed
            .remove("value")
            .unwrap_or_else(|| toml::Value::String(raw.to_string())),
        Err(_) => toml::Value::String(raw.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn layers_file_then_env_then_flags() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("segsplat.toml");
        std::fs::write(
            &file,
            "http_addr = \"127.0.0.1:9000\"\n[jobs]\nmax_attempts = 7\nlease_secs = 30\n",
        )
        .unwrap();
        let config = Config::load(
            Some(&file),
            env(&[
                ("SEGSPLAT_JOBS__LEASE_SECS", "20"),
                ("SEGSPLAT_AUTH__TOKENS", "[\"secret\"]"),
                ("SEGSPLAT_GRPC_ADDR", "127.0.0.1:6000"),
                ("SEGSPLAT_SKIP_GPU_TESTS", "1"),
                ("HOME", "/root"),
            ]),
            &ConfigOverrides {
                grpc_addr: Some("127.0.0.1:7000".parse().unwrap()),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(config.http_addr.port(), 9000);
        assert_eq!(config.jobs.max_attempts, 7);
        assert_eq!(config.jobs.lease_secs, 20.0);
        assert_eq!(config.auth.tokens, vec!["secret".to_string()]);
        assert_eq!(config.grpc_addr.port(), 7000);
        assert_eq!(config.data_dir, PathBuf::from("./data"));
    }

    #[test]
    fn tenant_tokens_from_the_environment() {
        let config = Config::load(
            None,
            env(&[(
                "SEGSPLAT_AUTH__TOKEN",
                "[{token = \"k1\", tenant = \"acme\"}, {token = \"k2\", admin = true}]",
            )]),
            &ConfigOverrides::default(),
        )
        .unwrap();
        assert_eq!(config.auth.token.len(), 2);
        assert_eq!(config.auth.token[0].tenant_name(), "acme");
        assert!(config.auth.token[1].admin);
        assert_eq!(config.auth.token[1].tenant_name(), "default");
        assert!(config.auth.enabled());
    }

    #[test]
    fn invalid_values_name_their_key() {
        let error = Config::load(
            None,
            env(&[("SEGSPLAT_LIMITS__MAX_UPLOAD_BYTES", "0")]),
            &ConfigOverrides::default(),
        )
        .unwrap_err();
        assert_eq!(error.to_string(), "limits.max_upload_bytes: must be > 0");

        let error = Config::load(
            None,
            env(&[("SEGSPLAT_JOBS__HEARTBEAT_SECS", "120")]),
            &ConfigOverrides::default(),
        )
        .unwrap_err();
        assert!(
            error.to_string().starts_with("jobs.heartbeat_secs:"),
            "{error}"
        );

        let error = Config::load(
            None,
            env(&[("SEGSPLAT_SCENE__VIDEO_FRAMES__FRAME_STEP", "0")]),
            &ConfigOverrides::default(),
        )
        .unwrap_err();
        assert_eq!(
            error.to_string(),
            "scene.video_frames.frame_step: must be > 0"
        );
    }

    #[test]
    fn models_section_from_environment() {
        let config = Config::load(
            None,
            env(&[
                ("SEGSPLAT_MODELS__DIR", "/srv/models"),
                ("SEGSPLAT_MODELS__INTRA_THREADS", "4"),
                ("SEGSPLAT_MODELS__CUDA", "false"),
            ]),
            &ConfigOverrides::default(),
        )
        .unwrap();
        assert_eq!(config.models.dir, Some(PathBuf::from("/srv/models")));
        assert_eq!(config.models.intra_threads, 4);
        assert!(!config.models.cuda);
        assert!(
            Config::default().models.cuda,
            "CUDA is used where offered by default"
        );
        assert_eq!(config.models.ort_library, None);
        assert!(Config::default().models.dir.is_none());

        let error = Config::load(
            None,
            env(&[("SEGSPLAT_MODELS__INTER_THREADS", "5000")]),
            &ConfigOverrides::default(),
        )
        .unwrap_err();
        assert!(
            error.to_string().starts_with("models.inter_threads:"),
            "{error}"
        );
    }

    #[test]
    fn unknown_keys_are_rejected() {
        let error = Config::load(
            None,
            env(&[("SEGSPLAT_JOBS__LEASE_SECONDS", "5")]),
            &ConfigOverrides::default(),
        )
        .unwrap_err();
        assert!(error.to_string().contains("lease_seconds"), "{error}");
    }
}
