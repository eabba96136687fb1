//! The serving core REST and gRPC share for masks and exports: which job's results a scene
//! serves, loading them into the GPU scene cache, rendering and encoding masks, and reading the
//! trained files.

use std::sync::Arc;

use crate::job_kinds::segment_then_splat::KIND as SEGMENT_THEN_SPLAT;
use crate::jobs::job_output_prefix as output_prefix;
use crate::serving::{
    EncodedMask, LoadedScene, MaskFormat, MaskView, ObjectMasks, SceneCache, ServingError,
    SplatFormat, TrainedScene, encode_mask, encode_splats, object_file, parse_cameras,
};
use crate::store::blob::not_found_or_io;
use crate::store::jobs::JobRecord;
use crate::store::{BlobError, BlobStore, Caller, Database, StoreError};
use segsplat_method::cameras::{CAMERAS_FILE, SceneCamera};
use segsplat_method::segment_then_splat::objects::ObjectSummary;
use segsplat_scene::Level;

/// The whole scene as SPZ: downloadable beside [`DOWNLOADABLE_FILES`], encoded on request.
pub const SPZ_FILE: &str = "scene.spz";

/// Results files a client may download from a scene's trained version (the deformation
/// field's two files exist for dynamic scenes only).
pub const DOWNLOADABLE_FILES: [&str; 8] = [
    "scene.ply",
    "labels.npy",
    "cameras.json",
    "objects.json",
    "metrics.json",
    "skipped_pairs.json",
    "deformation.json",
    "deformation.bin",
];

/// Why a mask or export request got no answer; each maps to one REST status and one gRPC code.
#[derive(Debug, thiserror::Error)]
pub enum ServeFailure {
    #[error("scene {0} not found")]
    SceneNotFound(String),
    #[error("scene {0} has no finished segment_then_splat (or reconstruct) job yet")]
    NotTrained(String),
    #[error("{0} is not a downloadable file; choose one of {files}, {SPZ_FILE}", files = DOWNLOADABLE_FILES.join(", "))]
    UnknownFile(String),
    /// A time was asked of a scene whose frames carry none: nothing moves it.
    #[error("scene {0} is static; time applies to dynamic scenes only")]
    StaticScene(String),
    #[error("{file} is not among this scene's results (job {job_id})")]
    FileNotStored { file: String, job_id: String },
    #[error(transparent)]
    Serving(#[from] ServingError),
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The blob store is down; the request may be retried.
    #[error(transparent)]
    Blobs(BlobError),
    #[error("{0}")]
    Worker(String),
    /// The client's deadline passed before the render started; it was skipped.
    #[error("the call's deadline passed before the masks were rendered")]
    DeadlineExceeded,
    /// The client left (a REST client disconnected, a gRPC call was dropped) before the render
    /// started; it was skipped.
    #[error("the caller left before the masks were rendered")]
    CallerGone,
}

/// One object's encoded masks.
#[derive(Debug, Clone)]
pub struct EncodedObjectMasks {
    pub level: Level,
    pub object_id: u32,
    pub mask: EncodedMask,
    pub visible_mask: Option<EncodedMask>,
}

#[derive(Clone)]
pub struct Serving {
    database: Database,
    blobs: Arc<dyn BlobStore>,
    cache: Arc<SceneCache>,
    max_mask_side: u32,
    /// Where downloads from an object store are staged before they stream to the client.
    scratch_dir: std::path::PathBuf,
}

/// A trained file opened for streaming to a client: it is never held whole in memory.
#[derive(Debug)]
pub struct OpenedFile {
    pub file: std::fs::File,
    pub len: u64,
}

impl Serving {
    pub fn new(
        database: Database,
        blobs: Arc<dyn BlobStore>,
        cache: Arc<SceneCache>,
        max_mask_side: u32,
        scratch_dir: std::path::PathBuf,
    ) -> Self {
        Self {
            database,
            blobs,
            cache,
            max_mask_side,
            scratch_dir,
        }
    }

    /// The serving core as `config` sets it up: a scene cache with the configured budget that
    /// opens the first adapter the workers' filter admits on its first mask request.
    pub fn from_config(
        config: &crate::config::Config,
        database: Database,
        blobs: Arc<dyn BlobStore>,
    ) -> Self {
        let adapters = config.workers.adapters.clone();
        let cache = Arc::new(SceneCache::new(
            config.query.cache_budget_mib.saturating_mul(1024 * 1024),
            move || segsplat_gpu::GpuContext::new(&adapters).map_err(|error| error.to_string()),
        ));
        Self::new(
            database,
            blobs,
            cache,
            config.query.max_mask_side,
            config.scratch_dir(),
        )
    }

    pub fn cache(&self) -> &SceneCache {
        &self.cache
    }

    /// The job whose results the scene serves: its latest finished `segment_then_splat` job
    /// (whose objects the object table holds), else its latest `reconstruct` job. A scene
    /// `caller` does not see is [`ServeFailure::SceneNotFound`]: every method here starts
    /// from this check.
    pub async fn serving_job(
        &self,
        scene_id: &str,
        caller: &Caller,
    ) -> Result<JobRecord, ServeFailure> {
        if self.database.get_scene(scene_id, caller).await?.is_none() {
            return Err(ServeFailure::SceneNotFound(scene_id.to_string()));
        }
        for kind in [SEGMENT_THEN_SPLAT, crate::job_kinds::reconstruct::KIND] {
            if let Some(job) = self.database.latest_succeeded_job(scene_id, kind).await? {
                return Ok(job);
            }
        }
        Err(ServeFailure::NotTrained(scene_id.to_string()))
    }

    /// The scene's served version, resident on the GPU.
    pub async fn loaded_scene(
        &self,
        scene_id: &str,
        caller: &Caller,
    ) -> Result<Arc<LoadedScene>, ServeFailure> {
        let job = self.serving_job(scene_id, caller).await?;
        self.load_job(job).await
    }

    async fn load_job(&self, job: JobRecord) -> Result<Arc<LoadedScene>, ServeFailure> {
        let cache = Arc::clone(&self.cache);
        let blobs = Arc::clone(&self.blobs);
        blocking(move || {
            let prefix = output_prefix(&job.id);
            Ok(cache.get_or_load(&job.id, || {
                TrainedScene::from_blobs(blobs.as_ref(), &prefix)
            })?)
        })
        .await
    }

    /// Renders and encodes the masks of `objects` for `view` (at `time` for a dynamic scene).
    // The scene, who asks, and the render settings each caller passes straight from its request.
    #[allow(clippy::too_many_arguments)]
    pub async fn render_masks(
        &self,
        scene_id: &str,
        caller: &Caller,
        view: MaskView,
        time: Option<f32>,
        objects: Vec<(Level, u32)>,
        visible_too: bool,
        format: MaskFormat,
    ) -> Result<Vec<EncodedObjectMasks>, ServeFailure> {
        let rendered = self
            .render_bit_masks(scene_id, caller, view, time, objects, visible_too)
            .await?;
        blocking(move || {
            rendered
                .iter()
                .map(|masks| {
                    Ok(EncodedObjectMasks {
                        level: masks.level,
                        object_id: masks.object_id,
                        mask: encode_mask(&masks.full, format)?,
                        visible_mask: masks
                            .visible
                            .as_ref()
                            .map(|visible| encode_mask(visible, format))
                            .transpose()?,
                    })
                })
                .collect::<Result<Vec<_>, ServingError>>()
                .map_err(ServeFailure::from)
        })
        .await
    }

    /// Renders the masks of `objects` for `view` (unencoded: evaluation and the CLI). A
    /// dynamic scene renders at `time`, else at the frame's own time for a frame view, else at
    /// its first time; a static scene ignores `time`.
    pub async fn render_bit_masks(
        &self,
        scene_id: &str,
        caller: &Caller,
        view: MaskView,
        time: Option<f32>,
        objects: Vec<(Level, u32)>,
        visible_too: bool,
    ) -> Result<Vec<ObjectMasks>, ServeFailure> {
        super::observe::timed("segsplat_mask_render_seconds", async move {
            let job = self.serving_job(scene_id, caller).await?;
            // Unknown ids would render as empty masks; say so instead.
            let known = self.database.list_objects(scene_id, None).await?;
            if let Some(&(level, object_id)) = objects.iter().find(|(level, object_id)| {
                !known
                    .iter()
                    .any(|known| known.level == *level && known.object_id == *object_id)
            }) {
                return Err(ServingError::NoSuchObject { level, object_id }.into());
            }
            let scene = self.load_job(job).await?;
            let cache = Arc::clone(&self.cache);
            let max_mask_side = self.max_mask_side;
            // Renders queue for the GPU: one whose caller has given up (its deadline passed, or
            // it left and dropped this future) is not started, checked when the thread starts
            // and again once it holds the renderer, after waiting behind other renders.
            let deadline = super::observe::deadline();
            let presence = CallerPresence::default();
            let caller_here = presence.watch();
            let masks = blocking(move || {
                let gone = || {
                    if super::observe::deadline_passed(deadline) {
                        Some(ServeFailure::DeadlineExceeded)
                    } else if !caller_here.present() {
                        Some(ServeFailure::CallerGone)
                    } else {
                        None
                    }
                };
                if let Some(failure) = gone() {
                    return Err(failure);
                }
                let camera = view.render_camera(&scene.cameras, max_mask_side)?;
                let time = scene.effective_time(time, view.frame_time(&scene.cameras));
                let wanted = || gone().is_none();
                match cache.render_masks(&scene, &camera, &objects, visible_too, time, &wanted)? {
                    Some(masks) => Ok(masks),
                    None => Err(gone().unwrap_or(ServeFailure::CallerGone)),
                }
            })
            .await?;
            drop(presence);
            Ok(masks)
        })
        .await
    }

    /// The objects where they are at `time` (or the frame's time) when the scene is dynamic;
    /// `None` for a static scene, whose stored object table holds at every time.
    pub async fn objects_at(
        &self,
        scene_id: &str,
        caller: &Caller,
        time: Option<f32>,
        view: Option<&MaskView>,
    ) -> Result<Option<Vec<ObjectSummary>>, ServeFailure> {
        // Static scenes answer from the object table without claiming the GPU.
        let dynamic = self
            .database
            .get_scene(scene_id, caller)
            .await?
            .is_some_and(|scene| scene.summary.time_count > 0);
        if !dynamic {
            return Ok(None);
        }
        let scene = self.loaded_scene(scene_id, caller).await?;
        let frame_time = view.and_then(|view| view.frame_time(&scene.cameras));
        let Some(time) = scene.effective_time(time, frame_time) else {
            return Ok(None);
        };
        let cache = Arc::clone(&self.cache);
        blocking(move || Ok(cache.objects_at(&scene, time)?)).await
    }

    /// One trained file of the scene's served version.
    pub async fn trained_file(
        &self,
        scene_id: &str,
        caller: &Caller,
        file: &str,
    ) -> Result<Vec<u8>, ServeFailure> {
        let (key, job_id) = self.trained_file_key(scene_id, caller, file).await?;
        let blobs = Arc::clone(&self.blobs);
        let file = file.to_string();
        blocking(move || {
            blobs
                .get_bytes(&key)
                .map_err(|error| trained_file_failure(error, &file, &job_id))
        })
        .await
    }

    /// Checks `view` as a render would (a frame the scene has, sides within `max_mask_side`,
    /// positive focal lengths, a rigid pose) without rendering: for a query that matched
    /// nothing, whose view would otherwise never be looked at. A free camera needs no scene; a
    /// frame view reads the scene's cameras (`cameras`, no GPU).
    pub async fn check_view(
        &self,
        scene_id: &str,
        caller: &Caller,
        view: &MaskView,
    ) -> Result<(), ServeFailure> {
        let cameras = match view {
            MaskView::Pose { .. } => Vec::new(),
            MaskView::Frame { .. } => self.cameras(scene_id, caller).await?,
        };
        view.render_camera(&cameras, self.max_mask_side)?;
        Ok(())
    }

    /// The cameras of the scene's served version, in frame order (what a frame index means).
    /// Read from the loaded scene when it is in the cache, else from its stored `cameras.json`
    /// (so asking for cameras never loads Gaussians onto the GPU).
    pub async fn cameras(
        &self,
        scene_id: &str,
        caller: &Caller,
    ) -> Result<Vec<SceneCamera>, ServeFailure> {
        let job = self.serving_job(scene_id, caller).await?;
        if let Some(loaded) = self.cache.peek(&job.id) {
            return Ok(loaded.cameras.clone());
        }
        let bytes = self.trained_file(scene_id, caller, CAMERAS_FILE).await?;
        Ok(parse_cameras(&bytes)?)
    }

    /// A trained file of the scene's serving job, opened for streaming. From the local blob
    /// directory the stored file itself is opened; from an object store it is first fetched
    /// (streamed) into the scratch folder and unlinked once open, so nothing is left behind
    /// whatever becomes of the download.
    pub async fn open_trained_file(
        &self,
        scene_id: &str,
        caller: &Caller,
        file: &str,
    ) -> Result<OpenedFile, ServeFailure> {
        let (key, job_id) = self.trained_file_key(scene_id, caller, file).await?;
        let blobs = Arc::clone(&self.blobs);
        let scratch_dir = self.scratch_dir.clone();
        let file = file.to_string();
        blocking(move || {
            let opened = match blobs.local_path(&key) {
                Some(path) => std::fs::File::open(&path).map_err(|source| {
                    trained_file_failure(not_found_or_io(&key, source), &file, &job_id)
                })?,
                None => {
                    std::fs::create_dir_all(&scratch_dir).map_err(|error| {
                        ServeFailure::Worker(format!("cannot create the scratch folder: {error}"))
                    })?;
                    let staged = scratch_dir.join(format!(
                        "download-{}-{}",
                        crate::store::process_tag::process_tag(),
                        uuid::Uuid::new_v4().simple()
                    ));
                    let opened = blobs.get_to_path(&key, &staged).and_then(|()| {
                        std::fs::File::open(&staged).map_err(|source| BlobError::Io {
                            key: key.clone(),
                            source,
                        })
                    });
                    let _ = std::fs::remove_file(&staged);
                    opened.map_err(|error| trained_file_failure(error, &file, &job_id))?
                }
            };
            let len = opened
                .metadata()
                .map_err(|error| ServeFailure::Worker(format!("cannot stat {key}: {error}")))?
                .len();
            Ok(OpenedFile { file: opened, len })
        })
        .await
    }

    /// The blob key of `file` among the outputs of the scene's serving job, and that job's id.
    async fn trained_file_key(
        &self,
        scene_id: &str,
        caller: &Caller,
        file: &str,
    ) -> Result<(String, String), ServeFailure> {
        if !DOWNLOADABLE_FILES.contains(&file) {
            return Err(ServeFailure::UnknownFile(file.to_string()));
        }
        let job = self.serving_job(scene_id, caller).await?;
        Ok((format!("{}/{file}", output_prefix(&job.id)), job.id))
    }

    /// One object's Gaussians as their own file in `format`.
    pub async fn object_export(
        &self,
        scene_id: &str,
        caller: &Caller,
        level: Level,
        object_id: u32,
        format: SplatFormat,
    ) -> Result<Vec<u8>, ServeFailure> {
        let trained = self.trained_scene(scene_id, caller).await?;
        blocking(move || {
            Ok(object_file(
                &trained.model,
                trained.sh_degree,
                level,
                object_id,
                format,
            )?)
        })
        .await
    }

    /// The whole scene as compressed SPZ ([`SPZ_FILE`]), encoded from its stored PLY.
    pub async fn scene_spz(
        &self,
        scene_id: &str,
        caller: &Caller,
    ) -> Result<Vec<u8>, ServeFailure> {
        let trained = self.trained_scene(scene_id, caller).await?;
        blocking(move || {
            Ok(encode_splats(
                &trained.model,
                trained.sh_degree,
                SplatFormat::Spz,
            )?)
        })
        .await
    }

    /// The whole scene in `format` with its Gaussians moved to `time` by the deformation field
    /// (means, log-scales, rotations; opacity and colour stay canonical), in the canonical
    /// file's layout and Gaussian order, so `labels.npy` still lines up. Built in memory from
    /// the scene cache's GPU copy. `None` when the served version has no field (a dynamic scene
    /// trained static): its stored file is the scene at every time.
    pub async fn scene_at_time(
        &self,
        scene_id: &str,
        caller: &Caller,
        time: f32,
        format: SplatFormat,
    ) -> Result<Option<Vec<u8>>, ServeFailure> {
        // Checked before the trained version, so a static scene says why whatever its state.
        if !self.is_dynamic(scene_id, caller).await? {
            return Err(ServeFailure::StaticScene(scene_id.to_string()));
        }
        let scene = self.loaded_scene(scene_id, caller).await?;
        let cache = Arc::clone(&self.cache);
        blocking(move || {
            let Some(model) = cache.model_at(&scene, time)? else {
                return Ok(None);
            };
            Ok(Some(encode_splats(&model, scene.sh_degree, format)?))
        })
        .await
    }

    /// Whether the scene's frames carry times; [`ServeFailure::SceneNotFound`] when `caller`
    /// does not see it.
    async fn is_dynamic(&self, scene_id: &str, caller: &Caller) -> Result<bool, ServeFailure> {
        match self.database.get_scene(scene_id, caller).await? {
            Some(scene) => Ok(scene.summary.time_count > 0),
            None => Err(ServeFailure::SceneNotFound(scene_id.to_string())),
        }
    }

    async fn trained_scene(
        &self,
        scene_id: &str,
        caller: &Caller,
    ) -> Result<TrainedScene, ServeFailure> {
        let job = self.serving_job(scene_id, caller).await?;
        let blobs = Arc::clone(&self.blobs);
        blocking(move || {
            Ok(TrainedScene::from_blobs(
                blobs.as_ref(),
                &output_prefix(&job.id),
            )?)
        })
        .await
    }
}

/// A trained file that could not be read: not stored, the store down, or another failure.
fn trained_file_failure(error: BlobError, file: &str, job_id: &str) -> ServeFailure {
    match error {
        BlobError::NotFound { .. } => ServeFailure::FileNotStored {
            file: file.to_string(),
            job_id: job_id.to_string(),
        },
        unavailable @ BlobError::Unavailable { .. } => ServeFailure::Blobs(unavailable),
        other => ServeFailure::Worker(other.to_string()),
    }
}

/// Held by a call while its blocking work runs: dropped with the call's future (a REST client
/// that disconnected, a gRPC call past its deadline), it tells the work its caller is gone.
#[derive(Default)]
struct CallerPresence(Arc<std::sync::atomic::AtomicBool>);

/// The blocking side of a [`CallerPresence`].
struct CallerWatch(Arc<std::sync::atomic::AtomicBool>);

impl CallerPresence {
    fn watch(&self) -> CallerWatch {
        CallerWatch(Arc::clone(&self.0))
    }
}

impl Drop for CallerPresence {
    fn drop(&mut self) {
        self.0.store(true, std::sync::atomic::Ordering::Release);
    }
}

impl CallerWatch {
    fn present(&self) -> bool {
        !self.0.load(std::sync::atomic::Ordering::Acquire)
    }
}

async fn blocking<T: Send + 'static>(
    work: impl FnOnce() -> Result<T, ServeFailure> + Send + 'static,
) -> Result<T, ServeFailure> {
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|error| ServeFailure::Worker(format!("worker thread failed: {error}")))?
}
