//! Splat exports: a scene, or the Gaussians of one object at one level, as an Inria-layout PLY
//! (opens in any splat viewer) or as compressed SPZ (web viewers such as Spark).

use super::ServingError;
use segsplat_engine::GaussianModel;
use segsplat_engine::ply::write_ply;
use segsplat_engine::spz::write_spz;
use segsplat_scene::Level;

/// The Gaussians of `object_id` at `level`, in scene order, with all their ids kept.
pub fn object_model(model: &GaussianModel, level: Level, object_id: u32) -> GaussianModel {
    let mut object = GaussianModel::default();
    for (index, ids) in model.object_ids.iter().enumerate() {
        if ids[level.index()] == object_id {
            object.means.push(model.means[index]);
            object.log_scales.push(model.log_scales[index]);
            object.rotations.push(model.rotations[index]);
            object.opacity_logits.push(model.opacity_logits[index]);
            object.sh_coefficients.push(model.sh_coefficients[index]);
            object.object_ids.push(*ids);
        }
    }
    object
}

/// A file format for Gaussians.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SplatFormat {
    /// The 3DGS "Inria" PLY, every SH coefficient as f32.
    Ply,
    /// Niantic's compressed SPZ (version 2), SH up to the scene's degree.
    Spz,
}

impl SplatFormat {
    pub fn extension(self) -> &'static str {
        match self {
            SplatFormat::Ply => "ply",
            SplatFormat::Spz => "spz",
        }
    }
}

/// `model`'s bytes in `format` (`sh_degree`: the degree the scene was trained to).
pub fn encode_splats(
    model: &GaussianModel,
    sh_degree: u32,
    format: SplatFormat,
) -> Result<Vec<u8>, ServingError> {
    let mut bytes = Vec::new();
    let written = match format {
        SplatFormat::Ply => write_ply(model, &mut bytes).map_err(|error| error.to_string()),
        SplatFormat::Spz => {
            write_spz(model, sh_degree, &mut bytes).map_err(|error| error.to_string())
        }
    };
    written.map_err(ServingError::Encoding)?;
    Ok(bytes)
}

/// The object's bytes in `format`; `NotFound` when no Gaussian carries that id.
pub fn object_file(
    model: &GaussianModel,
    sh_degree: u32,
    level: Level,
    object_id: u32,
    format: SplatFormat,
) -> Result<Vec<u8>, ServingError> {
    let object = object_model(model, level, object_id);
    if object.is_empty() {
        return Err(ServingError::NoSuchObject { level, object_id });
    }
    encode_splats(&object, sh_degree, format)
}

#[cfg(test)]
mod tests {
    use super::*;
    use segsplat_engine::OBJECT_NONE;
    use segsplat_engine::ply::read_ply;

    #[test]
    fn only_the_object_s_gaussians_are_written() {
        let mut model = GaussianModel::default();
        for (index, ids) in [[1, 5, 9], [2, 5, 9], [1, 6, OBJECT_NONE]]
            .iter()
            .enumerate()
        {
            model.push_simple(
                [index as f32, 0.0, 0.0],
                [0.0; 3],
                [1.0, 0.0, 0.0, 0.0],
                1.0,
                [0.5; 3],
                *ids,
            );
        }
        let bytes = object_file(&model, 3, Level::Small, 1, SplatFormat::Ply).unwrap();
        let back = read_ply(bytes.as_slice()).unwrap().model;
        let xs: Vec<f32> = back.means.iter().map(|mean| mean[0]).collect();
        assert_eq!(xs, vec![0.0, 2.0]);
        assert_eq!(object_model(&model, Level::Middle, 5).len(), 2);
        assert!(matches!(
            object_file(&model, 3, Level::Large, 4, SplatFormat::Spz),
            Err(ServingError::NoSuchObject { object_id: 4, .. })
        ));
    }
}
