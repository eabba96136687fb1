//! `segsplat export SCENE`: a scene's trained version as files: the whole scene (`scene.ply`),
//! the labels sidecar (`labels.npy`, object ids in PLY order), cameras, object table and
//! reports, and chosen objects as their own PLYs.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use segsplat_scene::Level;
use segsplat_service::usecases::serving::DOWNLOADABLE_FILES;

use super::local::{LocalService, StoreArgs};
use segsplat_service::store::Caller;

#[derive(Args)]
pub struct ExportArgs {
    /// Scene id or unique scene name.
    pub scene: String,
    /// Output folder (created).
    #[arg(long, default_value = "export")]
    pub out: PathBuf,
    /// An object to write as `<level>-<id>.ply`, as `level:id` (e.g. `small:3`); repeatable.
    #[arg(long = "object", value_parser = parse_object)]
    pub objects: Vec<(Level, u32)>,
    #[command(flatten)]
    pub store: StoreArgs,
}

fn parse_object(text: &str) -> Result<(Level, u32), String> {
    let (level, id) = text
        .split_once(':')
        .ok_or_else(|| format!("{text:?}: expected level:id, e.g. small:3"))?;
    let level = Level::ALL
        .into_iter()
        .find(|candidate| candidate.name() == level)
        .ok_or_else(|| format!("{level:?}: expected small, middle or large"))?;
    let id = id
        .parse()
        .map_err(|_| format!("{id:?}: not an object id"))?;
    Ok((level, id))
}

pub fn run(args: ExportArgs, config_file: Option<PathBuf>) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    runtime.block_on(async move {
        let local = LocalService::open(config_file.as_deref(), &args.store).await?;
        let scene_id = local.resolve_scene(&args.scene).await?;
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("cannot create {}", args.out.display()))?;
        let mut written = Vec::new();
        for file in DOWNLOADABLE_FILES {
            match local
                .core
                .serving
                .trained_file(&scene_id, &Caller::system(), file)
                .await
            {
                Ok(bytes) => {
                    let path = args.out.join(file);
                    std::fs::write(&path, bytes)
                        .with_context(|| format!("cannot write {}", path.display()))?;
                    written.push(path);
                }
                // Reports a reconstruct job does not write (objects, skipped pairs).
                Err(segsplat_service::usecases::serving::ServeFailure::FileNotStored {
                    ..
                }) => {}
                Err(error) => return Err(error.into()),
            }
        }
        for &(level, object_id) in &args.objects {
            let bytes = local
                .core
                .serving
                .object_ply(&scene_id, &Caller::system(), level, object_id)
                .await?;
            let path = args.out.join(format!("{}-{object_id}.ply", level.name()));
            std::fs::write(&path, bytes)
                .with_context(|| format!("cannot write {}", path.display()))?;
            written.push(path);
        }
        for path in written {
            println!("{}", path.display());
        }
        Ok(())
    })
}
