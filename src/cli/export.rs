//! `segsplat export SCENE`: a scene's trained version as files: the whole scene (`scene.ply`, or
//! `scene.spz` with `--format spz`), the labels sidecar (`labels.npy`, object ids in splat
//! order), cameras, object table and reports, and chosen objects as their own splat files.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use segsplat_scene::Level;
use segsplat_service::serving::SplatFormat;
use segsplat_service::usecases::serving::{DOWNLOADABLE_FILES, SPZ_FILE};

use super::local::{LocalService, StoreArgs};
use segsplat_service::store::Caller;

#[derive(Args)]
pub struct ExportArgs {
    /// Scene id or unique scene name.
    pub scene: String,
    /// Output folder (created).
    #[arg(long, default_value = "export")]
    pub out: PathBuf,
    /// An object to write as `<level>-<id>.ply` (or `.spz`), as `level:id` (e.g. `small:3`);
    /// repeatable.
    #[arg(long = "object", value_parser = parse_object)]
    pub objects: Vec<(Level, u32)>,
    /// Splat file format for the scene and the objects: `ply` (Inria layout) or `spz`
    /// (compressed, about a tenth of the size; web viewers such as Spark load it).
    #[arg(long, value_enum, default_value_t = ExportFormat::Ply)]
    pub format: ExportFormat,
    #[command(flatten)]
    pub store: StoreArgs,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum ExportFormat {
    Ply,
    Spz,
}

impl From<ExportFormat> for SplatFormat {
    fn from(format: ExportFormat) -> Self {
        match format {
            ExportFormat::Ply => SplatFormat::Ply,
            ExportFormat::Spz => SplatFormat::Spz,
        }
    }
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
        let format = SplatFormat::from(args.format);
        let mut written = Vec::new();
        if format == SplatFormat::Spz {
            let path = args.out.join(SPZ_FILE);
            let bytes = local
                .core
                .serving
                .scene_spz(&scene_id, &Caller::system())
                .await?;
            std::fs::write(&path, bytes)
                .with_context(|| format!("cannot write {}", path.display()))?;
            written.push(path);
        }
        // With SPZ the scene's PLY is left out: the SPZ stands for it.
        let files = DOWNLOADABLE_FILES
            .into_iter()
            .filter(|&file| !(format == SplatFormat::Spz && file == "scene.ply"));
        for file in files {
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
                .object_export(&scene_id, &Caller::system(), level, object_id, format)
                .await?;
            let path = args.out.join(format!(
                "{}-{object_id}.{}",
                level.name(),
                format.extension()
            ));
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
