//! Trained scenes held on the GPU for mask requests: least recently used first out once the
//! Gaussians of the cached scenes pass a byte budget. Loading (blob reads, PLY parse, upload)
//! happens once per scene version; a request then costs one render per object (plus one of the
//! whole scene for visible-only masks).
//!
//! The GPU is opened on the first request, so an API process that never renders masks never
//! claims an adapter. Renders share one renderer (its buffers grow to the largest view) behind a
//! mutex: a single GPU queue runs them one after another anyway.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use lru::LruCache;

use super::ServingError;
use super::scene_motion::SceneMotion;
use super::trained_scene::TrainedScene;
use segsplat_engine::render::Renderer;
use segsplat_engine::{GaussianModel, GpuGaussians, ObjectFilter, RenderCamera};
use segsplat_gpu::{GpuContext, release_context, sole_owner};
use segsplat_method::cameras::SceneCamera;
use segsplat_method::segment_then_splat::objects::{
    ObjectSummary, full_mask, render_layer, summarize_objects, visible_mask,
};
use segsplat_scene::Level;
use segsplat_vision::segment::BitMask;

/// GPU bytes per Gaussian: 59 f32 parameters (mean, log-scale, rotation, opacity, 48 SH) and
/// three u32 object ids.
const BYTES_PER_GAUSSIAN: u64 = 59 * 4 + 3 * 4;

/// A scene version resident on the GPU.
pub struct LoadedScene {
    /// What the cache knows it by (a job id, or a folder path for the CLI).
    pub key: String,
    pub cameras: Vec<SceneCamera>,
    pub gaussian_count: usize,
    /// SH degree the stored PLY carries (what an SPZ of the scene keeps).
    pub sh_degree: u32,
    gaussians: GpuGaussians,
    /// The deformation field of a dynamic scene.
    motion: Option<Mutex<SceneMotion>>,
    bytes: u64,
}

impl LoadedScene {
    /// The span of training times of a dynamic scene; `None` for a static one.
    pub fn time_range(&self) -> Option<[f32; 2]> {
        self.motion.as_ref().map(|motion| lock(motion).time_range)
    }

    /// The time a request means: the asked one, else the frame's, else the scene's first.
    /// Static scenes have no time (anything asked is ignored: they look the same at all times).
    pub fn effective_time(&self, asked: Option<f32>, frame_time: Option<f32>) -> Option<f32> {
        let [first, _] = self.time_range()?;
        Some(asked.or(frame_time).unwrap_or(first))
    }
}

impl std::fmt::Debug for LoadedScene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoadedScene")
            .field("key", &self.key)
            .field("gaussian_count", &self.gaussian_count)
            .field("bytes", &self.bytes)
            .finish_non_exhaustive()
    }
}

/// One object's masks for one view.
#[derive(Debug, Clone)]
pub struct ObjectMasks {
    pub level: Level,
    pub object_id: u32,
    /// Alpha > 0.5 of the object rendered alone: occluded parts included.
    pub full: BitMask,
    /// The part no other Gaussian hides, when asked for.
    pub visible: Option<BitMask>,
}

type GpuOpener = Box<dyn Fn() -> Result<GpuContext, String> + Send + Sync>;

struct Gpu {
    ctx: Arc<GpuContext>,
    renderer: Mutex<Renderer>,
}

/// What [`SceneCache::release_gpu`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GpuRelease {
    /// No mask was rendered: the GPU was never opened.
    NeverOpened,
    /// Scenes, renderer, queue and device were dropped, in that order.
    Released,
    /// A render still held part of it after the wait; that render drops it when it ends.
    StillHeld,
}

#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct CacheStats {
    pub scenes: usize,
    pub bytes: u64,
    pub loads: u64,
    pub hits: u64,
}

struct Resident {
    scenes: LruCache<String, Arc<LoadedScene>>,
    bytes: u64,
    loads: u64,
    hits: u64,
}

pub struct SceneCache {
    budget_bytes: u64,
    open_gpu: GpuOpener,
    gpu: Mutex<Option<Arc<Gpu>>>,
    resident: Mutex<Resident>,
    /// Set by [`SceneCache::release_gpu`]: a render arriving after it must not open the GPU again.
    released: AtomicBool,
}

impl std::fmt::Debug for SceneCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneCache")
            .field("budget_bytes", &self.budget_bytes)
            .field("stats", &self.stats())
            .finish_non_exhaustive()
    }
}

fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while holding one of these locks leaves plain data behind; keep serving.
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl SceneCache {
    /// A cache keeping at most `budget_bytes` of Gaussians resident (a single scene larger than
    /// the budget is still served, alone), opening its GPU with `open_gpu` on first use.
    pub fn new(
        budget_bytes: u64,
        open_gpu: impl Fn() -> Result<GpuContext, String> + Send + Sync + 'static,
    ) -> Self {
        Self {
            budget_bytes,
            open_gpu: Box::new(open_gpu),
            gpu: Mutex::new(None),
            resident: Mutex::new(Resident {
                scenes: LruCache::unbounded(),
                bytes: 0,
                loads: 0,
                hits: 0,
            }),
            released: AtomicBool::new(false),
        }
    }

    pub fn stats(&self) -> CacheStats {
        let resident = lock(&self.resident);
        CacheStats {
            scenes: resident.scenes.len(),
            bytes: resident.bytes,
            loads: resident.loads,
            hits: resident.hits,
        }
    }

    fn gpu(&self) -> Result<Arc<Gpu>, ServingError> {
        let mut slot = lock(&self.gpu);
        if let Some(gpu) = slot.as_ref() {
            return Ok(Arc::clone(gpu));
        }
        if self.released.load(Ordering::Acquire) {
            return Err(ServingError::NoGpu("the service is stopping".to_string()));
        }
        let ctx = (self.open_gpu)().map_err(ServingError::NoGpu)?;
        tracing::info!(adapter = %ctx.report.name, "mask rendering GPU ready");
        let renderer = Renderer::new(&ctx).map_err(|error| ServingError::Gpu(error.to_string()))?;
        let gpu = Arc::new(Gpu {
            ctx: Arc::new(ctx),
            renderer: Mutex::new(renderer),
        });
        *slot = Some(Arc::clone(&gpu));
        Ok(gpu)
    }

    /// Releases the GPU at shutdown, in order: the resident scenes' buffers, then the renderer's
    /// pipelines and buffers, then the device and queue ([`release_context`]), each once the
    /// renders still running (waited for up to `wait` in all) let go of it. Later requests get
    /// [`ServingError::NoGpu`] instead of opening it again.
    pub fn release_gpu(&self, wait: Duration) -> GpuRelease {
        let deadline = Instant::now() + wait;
        let left = || deadline.saturating_duration_since(Instant::now());
        let gpu = {
            let mut slot = lock(&self.gpu);
            self.released.store(true, Ordering::Release);
            slot.take()
        };
        let scenes: Vec<Arc<LoadedScene>> = {
            let mut resident = lock(&self.resident);
            resident.bytes = 0;
            std::iter::from_fn(|| resident.scenes.pop_lru().map(|(_, scene)| scene)).collect()
        };
        metrics::gauge!("segsplat_scene_cache_bytes").set(0.0);
        metrics::gauge!("segsplat_scene_cache_scenes").set(0.0);
        let Some(gpu) = gpu else {
            // Scenes are loaded only through an open GPU: with none there are none either.
            return GpuRelease::NeverOpened;
        };
        let mut all_released = true;
        for scene in scenes {
            all_released &= sole_owner(scene, left()).is_ok();
        }
        all_released &= match sole_owner(gpu, left()) {
            Ok(Gpu { ctx, renderer }) => {
                drop(renderer);
                release_context(ctx, left()).is_ok()
            }
            Err(_) => false,
        };
        if all_released {
            GpuRelease::Released
        } else {
            GpuRelease::StillHeld
        }
    }

    /// The scene known as `key` when it is resident, without counting a hit or refreshing it.
    pub fn peek(&self, key: &str) -> Option<Arc<LoadedScene>> {
        lock(&self.resident).scenes.peek(key).cloned()
    }

    /// The scene known as `key`, loading it with `load` (blocking) when it is not resident.
    pub fn get_or_load(
        &self,
        key: &str,
        load: impl FnOnce() -> Result<TrainedScene, ServingError>,
    ) -> Result<Arc<LoadedScene>, ServingError> {
        {
            let mut resident = lock(&self.resident);
            if let Some(scene) = resident.scenes.get(key).cloned() {
                resident.hits += 1;
                return Ok(scene);
            }
        }
        let gpu = self.gpu()?;
        let span = tracing::info_span!("load_scene", key);
        let _entered = span.enter();
        let started = std::time::Instant::now();
        let trained = load()?;
        if trained.model.is_empty() {
            return Err(ServingError::Corrupt {
                file: segsplat_method::scene_files::SCENE_FILE.to_string(),
                problem: "the scene has no Gaussians".to_string(),
            });
        }
        let gaussians = GpuGaussians::upload(&gpu.ctx, &trained.model, trained.model.len())
            .map_err(|error| ServingError::Gpu(error.to_string()))?;
        let gaussian_count = trained.model.len();
        let motion = match &trained.deformation {
            Some(stored) => Some(SceneMotion::new(&gpu.ctx, stored, trained.model)?),
            None => None,
        };
        let bytes = gaussian_count as u64 * BYTES_PER_GAUSSIAN
            + motion.as_ref().map_or(0, SceneMotion::extra_bytes);
        let scene = Arc::new(LoadedScene {
            key: key.to_string(),
            cameras: trained.cameras,
            gaussian_count,
            sh_degree: trained.sh_degree,
            bytes,
            gaussians,
            motion: motion.map(Mutex::new),
        });
        tracing::info!(
            gaussians = scene.gaussian_count,
            seconds = started.elapsed().as_secs_f64(),
            "scene loaded for serving"
        );
        let mut resident = lock(&self.resident);
        if let Some(existing) = resident.scenes.get(key).cloned() {
            // Another request loaded it meanwhile; keep one copy.
            return Ok(existing);
        }
        resident.loads += 1;
        resident.bytes += scene.bytes;
        resident.scenes.put(key.to_string(), Arc::clone(&scene));
        let mut evicted_any = false;
        while resident.bytes > self.budget_bytes && resident.scenes.len() > 1 {
            let Some((evicted_key, evicted)) = resident.scenes.pop_lru() else {
                break;
            };
            resident.bytes = resident.bytes.saturating_sub(evicted.bytes);
            evicted_any = true;
            tracing::info!(key = %evicted_key, "scene evicted from the mask cache");
        }
        if evicted_any && let Some(gpu) = lock(&self.gpu).as_ref() {
            // Cached bind groups would keep the evicted scene's buffers alive for thousands of
            // submissions (segsplat_gpu::bind_cache::KEEP_SUBMISSIONS).
            gpu.ctx.release_cached_bind_groups();
        }
        metrics::gauge!("segsplat_scene_cache_bytes").set(resident.bytes as f64);
        metrics::gauge!("segsplat_scene_cache_scenes").set(resident.scenes.len() as f64);
        Ok(scene)
    }

    /// Renders each object's mask from `camera` (and its visible part when `visible_too`), at
    /// `time` for a dynamic scene (see [`LoadedScene::effective_time`]). `None` when `wanted`
    /// says no once this call holds the renderer (renders wait there behind one another) or
    /// before an object's render: its caller has left, and the GPU goes to the next one.
    pub fn render_masks(
        &self,
        scene: &LoadedScene,
        camera: &RenderCamera,
        objects: &[(Level, u32)],
        visible_too: bool,
        time: Option<f32>,
        wanted: &dyn Fn() -> bool,
    ) -> Result<Option<Vec<ObjectMasks>>, ServingError> {
        let gpu = self.gpu()?;
        let mut renderer = lock(&gpu.renderer);
        if !wanted() {
            return Ok(None);
        }
        let mut motion = scene.motion.as_ref().map(lock);
        let gaussians = match (motion.as_deref_mut(), time) {
            (Some(motion), Some(time)) => motion.at(&gpu.ctx, &scene.gaussians, time)?,
            _ => scene.gaussians.view(),
        };
        let render = |renderer: &mut Renderer, filter| {
            render_layer(&gpu.ctx, renderer, gaussians, camera, filter)
                .map_err(|error| ServingError::Gpu(error.to_string()))
        };
        let whole = if visible_too {
            Some(render(&mut renderer, ObjectFilter::All)?)
        } else {
            None
        };
        let to_mask = |values: Vec<bool>| {
            BitMask::from_bools(camera.width, camera.height, &values)
                .map_err(|error| ServingError::Gpu(error.to_string()))
        };
        objects
            .iter()
            .map(|&(level, object_id)| {
                if !wanted() {
                    return Ok(None);
                }
                let layer = render(
                    &mut renderer,
                    ObjectFilter::Object {
                        level,
                        id: object_id,
                    },
                )?;
                let visible = match &whole {
                    Some(whole) => Some(to_mask(visible_mask(&layer, whole))?),
                    None => None,
                };
                Ok(Some(ObjectMasks {
                    level,
                    object_id,
                    full: to_mask(full_mask(&layer))?,
                    visible,
                }))
            })
            .collect()
    }

    /// Every object's summary (centroid, bounds, colour) where it is at `time`: from the
    /// deformed Gaussians of a dynamic scene, `None` for a static one (its stored summaries hold).
    pub fn objects_at(
        &self,
        scene: &LoadedScene,
        time: f32,
    ) -> Result<Option<Vec<ObjectSummary>>, ServingError> {
        let model = self.model_at(scene, time)?;
        Ok(model.as_ref().map(summarize_objects))
    }

    /// The scene's Gaussians moved to `time` by its deformation field, read back from the GPU in
    /// the canonical order (object ids included); `None` for a scene without a field.
    pub fn model_at(
        &self,
        scene: &LoadedScene,
        time: f32,
    ) -> Result<Option<GaussianModel>, ServingError> {
        let Some(motion) = scene.motion.as_ref() else {
            return Ok(None);
        };
        let gpu = self.gpu()?;
        // The renderer lock orders this after any render using the moved geometry.
        let _renderer = lock(&gpu.renderer);
        let model = lock(motion).model_at(&gpu.ctx, &scene.gaussians, time)?;
        Ok(Some(model))
    }
}
