//! `scenes` rows: one per successfully uploaded dataset.

use serde::Serialize;

use super::sql::{DbRow, query};
use super::tenancy::{Caller, visible};
use super::{Database, StoreError};
use segsplat_scene::SceneSummary;

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SceneRecord {
    pub id: String,
    pub name: String,
    pub summary: SceneSummary,
    /// Blob-store prefix holding the scene's files (`{prefix}/files/<relative path>`).
    pub blob_prefix: String,
    pub created_at_ms: i64,
    /// The tenant whose token uploaded it ([`super::tenancy`]).
    pub tenant: String,
}

/// Why a scene could not be deleted.
#[derive(Debug, thiserror::Error)]
pub enum DeleteSceneError {
    #[error("scene {0} not found")]
    NotFound(String),
    #[error("scene {scene_id} has {active_jobs} queued or running job(s); cancel them first")]
    Busy { scene_id: String, active_jobs: i64 },
    #[error(transparent)]
    Store(#[from] StoreError),
}

impl From<sqlx::Error> for DeleteSceneError {
    fn from(error: sqlx::Error) -> Self {
        DeleteSceneError::Store(StoreError::Database(error))
    }
}

const COLUMNS: &str = "id, name, summary_json, blob_prefix, created_at_ms, tenant";

fn scene_from_row(row: &DbRow) -> Result<SceneRecord, StoreError> {
    let summary_json: String = row.try_get("summary_json")?;
    let id: String = row.try_get("id")?;
    let summary = serde_json::from_str(&summary_json).map_err(|error| StoreError::Corrupt {
        what: format!("summary of scene {id}"),
        message: error.to_string(),
    })?;
    Ok(SceneRecord {
        id,
        name: row.try_get("name")?,
        summary,
        blob_prefix: row.try_get("blob_prefix")?,
        created_at_ms: row.try_get("created_at_ms")?,
        tenant: row.try_get("tenant")?,
    })
}

impl Database {
    pub async fn insert_scene(&self, scene: &SceneRecord) -> Result<(), StoreError> {
        let summary_json =
            serde_json::to_string(&scene.summary).map_err(|error| StoreError::Corrupt {
                what: "scene summary".to_string(),
                message: error.to_string(),
            })?;
        let format = serde_json::to_value(scene.summary.format)
            .ok()
            .and_then(|value| value.as_str().map(str::to_string))
            .unwrap_or_default();
        query(
            "INSERT INTO scenes (id, name, format, frame_count, sparse_point_count, summary_json, \
             blob_prefix, created_at_ms, tenant) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
        )
        .bind(&scene.id)
        .bind(&scene.name)
        .bind(format)
        .bind(i64::from(scene.summary.frame_count))
        .bind(scene.summary.sparse_point_count as i64)
        .bind(summary_json)
        .bind(&scene.blob_prefix)
        .bind(scene.created_at_ms)
        .bind(&scene.tenant)
        .execute(self.sql())
        .await?;
        Ok(())
    }

    /// The scene, when it exists and `caller` sees its tenant.
    pub async fn get_scene(
        &self,
        id: &str,
        caller: &Caller,
    ) -> Result<Option<SceneRecord>, StoreError> {
        let row = query(format!(
            "SELECT {COLUMNS} FROM scenes WHERE id = ? AND {}",
            visible("tenant")
        ))
        .bind(id)
        .bind(caller.admin)
        .bind(&caller.tenant)
        .fetch_optional(self.sql())
        .await?;
        row.as_ref().map(scene_from_row).transpose()
    }

    /// The scenes `caller` sees, oldest first.
    pub async fn list_scenes(&self, caller: &Caller) -> Result<Vec<SceneRecord>, StoreError> {
        let rows = query(format!(
            "SELECT {COLUMNS} FROM scenes WHERE {} ORDER BY created_at_ms, id",
            visible("tenant")
        ))
        .bind(caller.admin)
        .bind(&caller.tenant)
        .fetch_all(self.sql())
        .await?;
        rows.iter().map(scene_from_row).collect()
    }

    /// Deletes the scene and everything recorded about it, unless a job of it is still queued
    /// or running. Returns the removed record and the ids of its removed jobs, so the caller can
    /// delete their blobs. Another tenant's scene is [`DeleteSceneError::NotFound`].
    pub async fn delete_scene(
        &self,
        id: &str,
        caller: &Caller,
    ) -> Result<(SceneRecord, Vec<String>), DeleteSceneError> {
        let mut transaction = self.begin().await?;
        let row = query(format!(
            "SELECT {COLUMNS} FROM scenes WHERE id = ? AND {}",
            visible("tenant")
        ))
        .bind(id)
        .bind(caller.admin)
        .bind(&caller.tenant)
        .fetch_optional(&mut transaction)
        .await?;
        let Some(row) = row else {
            return Err(DeleteSceneError::NotFound(id.to_string()));
        };
        let record = scene_from_row(&row)?;
        let active_jobs: i64 = query(
            "SELECT COUNT(*) FROM jobs WHERE scene_id = ? AND state IN ('queued', 'running')",
        )
        .bind(id)
        .fetch_one(&mut transaction)
        .await?
        .try_get(0)?;
        if active_jobs > 0 {
            return Err(DeleteSceneError::Busy {
                scene_id: id.to_string(),
                active_jobs,
            });
        }
        let job_ids = query("SELECT id FROM jobs WHERE scene_id = ?")
            .bind(id)
            .fetch_all(&mut transaction)
            .await?
            .iter()
            .map(|row| row.try_get(0))
            .collect::<Result<Vec<String>, _>>()?;
        for statement in [
            "DELETE FROM job_events WHERE job_id IN (SELECT id FROM jobs WHERE scene_id = ?)",
            "DELETE FROM jobs WHERE scene_id = ?",
            "DELETE FROM object_embeddings WHERE scene_id = ?",
            "DELETE FROM objects WHERE scene_id = ?",
            "DELETE FROM scenes WHERE id = ?",
        ] {
            query(statement).bind(id).execute(&mut transaction).await?;
        }
        transaction.commit().await?;
        Ok((record, job_ids))
    }
}
