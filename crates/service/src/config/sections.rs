//! The configuration's sections: one typed struct per top-level key but the addresses and the
//! data directory, each with its defaults.

use std::net::SocketAddr;

use serde::{Deserialize, Serialize};

use segsplat_gpu::AdapterFilter;
use segsplat_scene::VideoFrameOptions;

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
pub(super) fn valid_tenant_name(name: &str) -> bool {
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
