//! `segsplat query SCENE "text"`: the service's text query from the command line, with the
//! matched objects' masks written as PNGs for the chosen frames.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use segsplat_service::serving::{MaskView, mask_png};
use segsplat_service::usecases::query::{QueryRequest, query_with_masks};
use segsplat_vision::language::{DEFAULT_RELEVANCY_THRESHOLD, QueryOptions};
use serde::Serialize;

use super::local::{LocalService, StoreArgs};
use segsplat_service::store::Caller;

#[derive(Args)]
pub struct QueryArgs {
    /// Scene id or unique scene name.
    pub scene: String,
    /// What to look for, in plain words.
    pub text: String,
    /// `auto` (better of middle and large), `small`, `middle` or `large`.
    #[arg(long, default_value = "auto")]
    pub granularity: String,
    #[arg(long, default_value_t = 1)]
    pub top_k: usize,
    /// Minimum relevancy for a match (0.5 = no better than "object").
    #[arg(long, default_value_t = DEFAULT_RELEVANCY_THRESHOLD)]
    pub threshold: f32,
    /// Frames (0-based) to write masks for; repeat for several. None: no masks.
    #[arg(long = "frame")]
    pub frames: Vec<usize>,
    /// Longest side of the masks in pixels (default: the frame's size).
    #[arg(long)]
    pub max_side: Option<u32>,
    /// Also write the visible-only masks (`*-visible.png`).
    #[arg(long)]
    pub visible: bool,
    /// Dynamic scenes: the normalised time (0..1 spans the training frames) of the centroids,
    /// bounds and masks. Default: each frame's own time for masks, the first time otherwise.
    #[arg(long)]
    pub time: Option<f32>,
    /// Folder for the PNGs.
    #[arg(long, default_value = "masks")]
    pub out: PathBuf,
    #[command(flatten)]
    pub store: StoreArgs,
}

#[derive(Serialize)]
struct Answer {
    scene_id: String,
    matched: bool,
    model_id: String,
    objects: Vec<AnswerObject>,
}

#[derive(Serialize)]
struct AnswerObject {
    level: String,
    object_id: u32,
    score: f32,
    relevancy: f32,
    centroid: [f32; 3],
    bounds_min: [f32; 3],
    bounds_max: [f32; 3],
    /// Written mask files.
    masks: Vec<PathBuf>,
}

pub fn run(args: QueryArgs, config_file: Option<PathBuf>) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(run_async(args, config_file))
}

async fn run_async(args: QueryArgs, config_file: Option<PathBuf>) -> anyhow::Result<()> {
    let local = LocalService::open_with_models(config_file.as_deref(), &args.store).await?;
    let scene_id = local.resolve_scene(&args.scene).await?;
    let options = QueryOptions {
        granularity: args.granularity.parse()?,
        top_k: args.top_k,
        threshold: args.threshold,
    };
    // Placed at `--time`; masks are rendered below, per frame, as PNG files.
    let answer = query_with_masks(
        &local.core.database,
        &local.core.text_encoder,
        &local.core.serving,
        &Caller::system(),
        QueryRequest {
            scene_id: scene_id.clone(),
            text: args.text.clone(),
            options,
            time: args.time,
            masks: None,
        },
    )
    .await?;
    if !args.frames.is_empty() && !answer.objects.is_empty() {
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("cannot create {}", args.out.display()))?;
    }
    let mut objects = Vec::new();
    for (rank, found) in answer.objects.iter().enumerate() {
        let level = found.object.level;
        let object_id = found.object.object_id;
        let mut written = Vec::new();
        for &frame in &args.frames {
            let view = MaskView::Frame {
                index: frame,
                max_side: args.max_side,
            };
            let masks = local
                .core
                .serving
                .render_bit_masks(
                    &scene_id,
                    &Caller::system(),
                    view,
                    args.time,
                    vec![(level, object_id)],
                    args.visible,
                )
                .await?;
            let Some(masks) = masks.first() else {
                continue;
            };
            let stem = format!("{rank}-{}-{object_id}-frame{frame}", level.name());
            let mut outputs = vec![(args.out.join(format!("{stem}.png")), &masks.full)];
            if let Some(visible) = &masks.visible {
                outputs.push((args.out.join(format!("{stem}-visible.png")), visible));
            }
            for (path, mask) in outputs {
                std::fs::write(&path, mask_png(mask)?)
                    .with_context(|| format!("cannot write {}", path.display()))?;
                written.push(path);
            }
        }
        objects.push(AnswerObject {
            level: level.name().to_string(),
            object_id,
            score: found.score,
            relevancy: found.relevancy,
            centroid: found.object.centroid,
            bounds_min: found.object.bounds_min,
            bounds_max: found.object.bounds_max,
            masks: written,
        });
    }
    let answer = Answer {
        scene_id,
        matched: answer.matched,
        model_id: answer.model_id,
        objects,
    };
    println!("{}", serde_json::to_string_pretty(&answer)?);
    Ok(())
}
