//! `objects` and `object_embeddings`: what a finished pipeline job found in a scene.

use serde::Serialize;

use super::sql::query;
use super::{Database, StoreError};
use segsplat_scene::Level;

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectRecord {
    pub scene_id: String,
    pub level: Level,
    pub object_id: u32,
    pub gaussian_count: u64,
    pub centroid: [f32; 3],
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
    /// Linear RGB in 0..1.
    pub mean_color: [f32; 3],
}

#[derive(Debug, Clone, PartialEq)]
pub struct ObjectEmbedding {
    pub scene_id: String,
    pub level: Level,
    pub object_id: u32,
    pub model_id: String,
    pub vector: Vec<f32>,
}

fn level_from_name(name: &str) -> Result<Level, StoreError> {
    Level::ALL
        .into_iter()
        .find(|level| level.name() == name)
        .ok_or_else(|| StoreError::Corrupt {
            what: "object level".to_string(),
            message: format!("unknown level {name:?}"),
        })
}

/// Vectors are stored as little-endian f32 bytes, portable across databases and machines.
pub fn vector_to_bytes(vector: &[f32]) -> Vec<u8> {
    vector
        .iter()
        .flat_map(|value| value.to_le_bytes())
        .collect()
}

pub fn vector_from_bytes(bytes: &[u8]) -> Option<Vec<f32>> {
    if !bytes.len().is_multiple_of(4) {
        return None;
    }
    Some(
        bytes
            .chunks_exact(4)
            .map(|chunk| f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]))
            .collect(),
    )
}

impl Database {
    /// Replaces a scene's objects and embeddings in one transaction (a re-run job rewrites them).
    pub async fn replace_objects(
        &self,
        scene_id: &str,
        objects: &[ObjectRecord],
        embeddings: &[ObjectEmbedding],
    ) -> Result<(), StoreError> {
        let mut transaction = self.begin().await?;
        for statement in [
            "DELETE FROM object_embeddings WHERE scene_id = ?",
            "DELETE FROM objects WHERE scene_id = ?",
        ] {
            query(statement)
                .bind(scene_id)
                .execute(&mut transaction)
                .await?;
        }
        for object in objects {
            query(
                "INSERT INTO objects (scene_id, level, object_id, gaussian_count, centroid_x, \
                 centroid_y, centroid_z, bounds_min_x, bounds_min_y, bounds_min_z, bounds_max_x, \
                 bounds_max_y, bounds_max_z, mean_color_r, mean_color_g, mean_color_b) \
                 VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            )
            .bind(scene_id)
            .bind(object.level.name())
            .bind(i64::from(object.object_id))
            .bind(object.gaussian_count as i64)
            .bind(object.centroid[0])
            .bind(object.centroid[1])
            .bind(object.centroid[2])
            .bind(object.bounds_min[0])
            .bind(object.bounds_min[1])
            .bind(object.bounds_min[2])
            .bind(object.bounds_max[0])
            .bind(object.bounds_max[1])
            .bind(object.bounds_max[2])
            .bind(object.mean_color[0])
            .bind(object.mean_color[1])
            .bind(object.mean_color[2])
            .execute(&mut transaction)
            .await?;
        }
        for embedding in embeddings {
            query(
                "INSERT INTO object_embeddings (scene_id, level, object_id, model_id, dim, vector) \
                 VALUES (?, ?, ?, ?, ?, ?)",
            )
            .bind(scene_id)
            .bind(embedding.level.name())
            .bind(i64::from(embedding.object_id))
            .bind(&embedding.model_id)
            .bind(embedding.vector.len() as i64)
            .bind(vector_to_bytes(&embedding.vector))
            .execute(&mut transaction)
            .await?;
        }
        transaction.commit().await?;
        Ok(())
    }

    /// A scene's objects, optionally of one level, ordered by level then id.
    pub async fn list_objects(
        &self,
        scene_id: &str,
        level: Option<Level>,
    ) -> Result<Vec<ObjectRecord>, StoreError> {
        let rows = query(
            "SELECT * FROM objects WHERE scene_id = ? AND (? IS NULL OR level = ?) \
             ORDER BY level, object_id",
        )
        .bind(scene_id)
        .bind(level.map(Level::name))
        .bind(level.map(Level::name))
        .fetch_all(self.sql())
        .await?;
        rows.iter()
            .map(|row| {
                let level_name: String = row.try_get("level")?;
                let triple = |names: [&str; 3]| -> Result<[f32; 3], StoreError> {
                    Ok([
                        row.try_get::<f64, _>(names[0])? as f32,
                        row.try_get::<f64, _>(names[1])? as f32,
                        row.try_get::<f64, _>(names[2])? as f32,
                    ])
                };
                Ok(ObjectRecord {
                    scene_id: row.try_get("scene_id")?,
                    level: level_from_name(&level_name)?,
                    object_id: row.try_get::<i64, _>("object_id")?.max(0) as u32,
                    gaussian_count: row.try_get::<i64, _>("gaussian_count")?.max(0) as u64,
                    centroid: triple(["centroid_x", "centroid_y", "centroid_z"])?,
                    bounds_min: triple(["bounds_min_x", "bounds_min_y", "bounds_min_z"])?,
                    bounds_max: triple(["bounds_max_x", "bounds_max_y", "bounds_max_z"])?,
                    mean_color: triple(["mean_color_r", "mean_color_g", "mean_color_b"])?,
                })
            })
            .collect()
    }

    /// Embeddings of one scene for one model, for query scoring.
    pub async fn list_embeddings(
        &self,
        scene_id: &str,
        model_id: &str,
    ) -> Result<Vec<ObjectEmbedding>, StoreError> {
        let rows = query(
            "SELECT level, object_id, model_id, dim, vector FROM object_embeddings \
             WHERE scene_id = ? AND model_id = ? ORDER BY level, object_id",
        )
        .bind(scene_id)
        .bind(model_id)
        .fetch_all(self.sql())
        .await?;
        rows.iter()
            .map(|row| {
                let level_name: String = row.try_get("level")?;
                let bytes: Vec<u8> = row.try_get("vector")?;
                let dim: i64 = row.try_get("dim")?;
                let vector = vector_from_bytes(&bytes)
                    .filter(|vector| vector.len() as i64 == dim)
                    .ok_or_else(|| StoreError::Corrupt {
                        what: format!("embedding of scene {scene_id}"),
                        message: format!("{} bytes do not hold {dim} f32 values", bytes.len()),
                    })?;
                Ok(ObjectEmbedding {
                    scene_id: scene_id.to_string(),
                    level: level_from_name(&level_name)?,
                    object_id: row.try_get::<i64, _>("object_id")?.max(0) as u32,
                    model_id: row.try_get("model_id")?,
                    vector,
                })
            })
            .collect()
    }
}
