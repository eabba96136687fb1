//! Listing a scene's objects, placed where a dynamic scene has them at the asked time: the one
//! implementation behind REST `GET /v1/scenes/{id}/objects` and gRPC `ListObjects`.

use segsplat_scene::Level;

use super::query::placed;
use super::serving::{ServeFailure, Serving};
use crate::store::objects::ObjectRecord;
use crate::store::{Caller, Database, StoreError};

#[derive(Debug, thiserror::Error)]
pub enum ListObjectsError {
    #[error("scene {0} not found")]
    SceneNotFound(String),
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(transparent)]
    Serve(#[from] ServeFailure),
}

/// The scene's objects at `level` (all levels when `None`); with a `time`, each centroid and
/// box is where the object is then (static scenes keep their stored ones).
pub async fn list_objects(
    database: &Database,
    serving: &Serving,
    caller: &Caller,
    scene_id: &str,
    level: Option<Level>,
    time: Option<f32>,
) -> Result<Vec<ObjectRecord>, ListObjectsError> {
    if database.get_scene(scene_id, caller).await?.is_none() {
        return Err(ListObjectsError::SceneNotFound(scene_id.to_string()));
    }
    let records = database.list_objects(scene_id, level).await?;
    let moved = match time {
        Some(time) if !records.is_empty() => {
            serving
                .objects_at(scene_id, caller, Some(time), None)
                .await?
        }
        _ => None,
    };
    Ok(records
        .into_iter()
        .map(|record| placed(record, moved.as_deref()))
        .collect())
}
