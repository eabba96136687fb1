//! `segsplat eval SCENE --ground-truth PATH`: open-vocabulary segmentation scored the papers'
//! way (per frame the mean IoU over its queries, then the mean over frames) against LERF_OVS
//! labels or a 3D-OVS scene, plus the held-out PSNR/SSIM of the trained scene. `--oracle` picks,
//! for each ground-truth mask, the object of any level with the best IoU: the 3D segmentation
//! measured apart from language (the honest score without real CLIP weights).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use segsplat_eval::{
    FrameScore, GroundTruthFormat, SceneFrame, SegmentationReport, load_ground_truth,
    oracle_choice, report_table, scene_mismatches, score_frame, summarize,
};
use segsplat_scene::Level;
use segsplat_service::serving::{MaskView, SceneCamera};
use segsplat_service::usecases::objects::list_objects;
use segsplat_service::usecases::query::run_query;
use segsplat_vision::language::QueryOptions;
use segsplat_vision::segment::BitMask;
use serde::Serialize;

use super::local::{LocalService, StoreArgs};
use segsplat_service::store::Caller;

/// Objects rendered per request in the oracle's sweep over every object.
const ORACLE_BATCH: usize = 64;

#[derive(Args)]
pub struct EvalArgs {
    /// Scene id or unique scene name.
    pub scene: String,
    /// LERF_OVS label folder (`frame_*.json`) or 3D-OVS scene folder (`segmentations/`).
    #[arg(long)]
    pub ground_truth: PathBuf,
    /// For each ground-truth mask, the object of any level with the best IoU, instead of the
    /// text query's answer.
    #[arg(long)]
    pub oracle: bool,
    /// Granularity of the text queries: `auto` (the papers' choice), `small`, `middle`, `large`.
    #[arg(long, default_value = "auto")]
    pub granularity: String,
    /// Score the visible-only masks instead of the full (amodal) ones.
    #[arg(long)]
    pub visible: bool,
    /// Longest side of the rendered masks; IoU is taken at the labels' resolution.
    #[arg(long, default_value_t = 1024)]
    pub max_side: u32,
    /// Also write the report as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Score labels that do not match the scene's frames (another name at a frame's index,
    /// another image shape); without it such labels are refused.
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub store: StoreArgs,
}

#[derive(Serialize)]
struct EvalReport {
    scene_id: String,
    job_id: String,
    ground_truth: String,
    format: String,
    /// `language` (text query answers) or `oracle`.
    selection: String,
    granularity: String,
    masks: String,
    segmentation: SegmentationReport,
    /// For `language`: the object each query text selected.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    selected: BTreeMap<String, SelectedObject>,
    /// The trained scene's held-out PSNR/SSIM (`metrics.json`).
    held_out: Option<serde_json::Value>,
}

#[derive(Serialize, Clone)]
struct SelectedObject {
    level: Level,
    object_id: u32,
    score: f32,
    relevancy: f32,
}

pub fn run(args: EvalArgs, config_file: Option<PathBuf>) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(run_async(args, config_file))
}

async fn run_async(args: EvalArgs, config_file: Option<PathBuf>) -> anyhow::Result<()> {
    let local = if args.oracle {
        LocalService::open(config_file.as_deref(), &args.store).await?
    } else {
        LocalService::open_with_models(config_file.as_deref(), &args.store).await?
    };
    let scene_id = local.resolve_scene(&args.scene).await?;
    let job = local
        .core
        .serving
        .serving_job(&scene_id, &Caller::system())
        .await?;
    let cameras: Vec<SceneCamera> = serde_json::from_slice(
        &local
            .core
            .serving
            .trained_file(&scene_id, &Caller::system(), "cameras.json")
            .await?,
    )
    .context("cameras.json")?;
    let frame_names: Vec<String> = cameras.iter().map(|camera| camera.name.clone()).collect();
    let (format, ground_truth) = load_ground_truth(&args.ground_truth, &frame_names)
        .with_context(|| format!("ground truth in {}", args.ground_truth.display()))?;
    let scene_frames: Vec<SceneFrame> = cameras
        .iter()
        .map(|camera| SceneFrame {
            name: camera.name.clone(),
            width: camera.width,
            height: camera.height,
        })
        .collect();
    let problems = scene_mismatches(&ground_truth, &scene_frames);
    if !problems.is_empty() {
        let shown: Vec<&str> = problems.iter().take(5).map(String::as_str).collect();
        let more = problems.len().saturating_sub(shown.len());
        let listed = format!(
            "{}{}",
            shown.join("\n  "),
            if more > 0 {
                format!("\n  ... and {more} more")
            } else {
                String::new()
            }
        );
        if !args.force {
            anyhow::bail!(
                "the ground truth in {} does not belong to scene {}:\n  {listed}\n\
                 pass --force to score it anyway",
                args.ground_truth.display(),
                args.scene
            );
        }
        tracing::warn!("scoring labels that do not match the scene (--force):\n  {listed}");
    }
    let view = |frame_index: usize| MaskView::Frame {
        index: frame_index,
        max_side: Some(args.max_side),
    };
    let pick = |masks: &segsplat_service::serving::ObjectMasks| -> BitMask {
        match (&masks.visible, args.visible) {
            (Some(visible), true) => visible.clone(),
            _ => masks.full.clone(),
        }
    };

    let mut frames: Vec<FrameScore> = Vec::new();
    let mut selected = BTreeMap::new();
    if args.oracle {
        let core = &local.core;
        let system = Caller::system();
        let objects: Vec<(Level, u32)> = list_objects(
            &core.database,
            &core.serving,
            &system,
            &scene_id,
            None,
            None,
        )
        .await?
        .iter()
        .map(|object| (object.level, object.object_id))
        .collect();
        anyhow::ensure!(!objects.is_empty(), "scene {scene_id} has no objects");
        for frame in &ground_truth {
            let mut candidates = Vec::with_capacity(objects.len());
            for batch in objects.chunks(ORACLE_BATCH) {
                let masks = local
                    .core
                    .serving
                    .render_bit_masks(
                        &scene_id,
                        &Caller::system(),
                        view(frame.frame_index),
                        None,
                        batch.to_vec(),
                        args.visible,
                    )
                    .await?;
                candidates.extend(masks.iter().map(pick));
            }
            frames.push(score_frame(frame, |query| {
                oracle_choice(&query.mask, &candidates).map(|(best, _)| candidates[best].clone())
            }));
        }
    } else {
        let options = QueryOptions {
            granularity: args.granularity.parse()?,
            top_k: 1,
            // The benchmarks always take the best object: no "no match" here.
            threshold: 0.0,
        };
        for frame in &ground_truth {
            let mut predicted: BTreeMap<String, BitMask> = BTreeMap::new();
            for query in &frame.queries {
                if !selected.contains_key(&query.text) {
                    let outcome = run_query(
                        &local.core.database,
                        &local.core.text_encoder,
                        &scene_id,
                        &Caller::system(),
                        &query.text,
                        options,
                    )
                    .await
                    .context(
                        "text query (without CLIP weights, --oracle scores the segmentation)",
                    )?;
                    if let Some(best) = outcome.matches.first() {
                        selected.insert(
                            query.text.clone(),
                            SelectedObject {
                                level: best.object.level,
                                object_id: best.object.object_id,
                                score: best.score,
                                relevancy: best.relevancy,
                            },
                        );
                    }
                }
                let Some(object) = selected.get(&query.text) else {
                    continue;
                };
                let masks = local
                    .core
                    .serving
                    .render_bit_masks(
                        &scene_id,
                        &Caller::system(),
                        view(frame.frame_index),
                        None,
                        vec![(object.level, object.object_id)],
                        args.visible,
                    )
                    .await?;
                if let Some(masks) = masks.first() {
                    predicted.insert(query.text.clone(), pick(masks));
                }
            }
            frames.push(score_frame(frame, |query| {
                predicted.get(&query.text).cloned()
            }));
        }
    }
    let segmentation = summarize(frames);
    let held_out = match local
        .core
        .serving
        .trained_file(&scene_id, &Caller::system(), "metrics.json")
        .await
    {
        Ok(bytes) => serde_json::from_slice::<serde_json::Value>(&bytes)
            .ok()
            .and_then(|metrics| metrics.get("held_out").cloned()),
        Err(_) => None,
    };
    println!("{}", report_table(&segmentation));
    if let Some(held_out) = &held_out {
        println!(
            "held-out views: PSNR {} dB, SSIM {}",
            held_out["psnr"], held_out["ssim"]
        );
    }
    let report = EvalReport {
        scene_id,
        job_id: job.id,
        ground_truth: args.ground_truth.display().to_string(),
        format: match format {
            GroundTruthFormat::LerfOvs => "lerf_ovs",
            GroundTruthFormat::ThreeDOvs => "3d_ovs",
        }
        .to_string(),
        selection: if args.oracle { "oracle" } else { "language" }.to_string(),
        granularity: args.granularity.clone(),
        masks: if args.visible { "visible" } else { "full" }.to_string(),
        segmentation,
        selected,
        held_out,
    };
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_vec_pretty(&report)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
