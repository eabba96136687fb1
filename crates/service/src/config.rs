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

pub use segsplat_vision::models::ModelsConfig;

mod layers;
mod sections;

use layers::{insert_env_value, merge_tables};
pub use sections::*;

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
