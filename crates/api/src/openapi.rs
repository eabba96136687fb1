//! The OpenAPI document, generated from the handlers' annotations.

use axum::Json;
use utoipa::OpenApi;

use super::{error, exports, jobs, masks, objects, ops, query, scenes, workers};

#[derive(OpenApi)]
#[openapi(
    info(title = "segsplat", description = "Open-vocabulary 3D segmentation service"),
    paths(
        scenes::upload_scene,
        scenes::list_scenes,
        scenes::get_scene,
        scenes::delete_scene,
        jobs::create_job,
        jobs::get_job,
        jobs::list_jobs,
        jobs::cancel_job,
        jobs::job_events,
        objects::list_objects,
        query::query_scene,
        masks::render_masks,
        masks::object_mask_png,
        exports::trained_file,
        exports::object_ply,
        exports::object_spz,
        workers::list_workers,
        ops::healthz,
        ops::readyz,
        ops::metrics,
    ),
    components(schemas(
        error::ErrorBody,
        error::ErrorDetail,
        scenes::SceneResponse,
        scenes::SceneList,
        jobs::CreateJobRequest,
        jobs::JobResponse,
        jobs::JobList,
        workers::WorkerResponse,
        workers::WorkerList,
        objects::ObjectResponse,
        objects::ObjectList,
        query::QueryRequest,
        query::QueryMatchResponse,
        query::QueryResponse,
        masks::ViewRequest,
        segsplat_service::serving::PinholeIntrinsics,
        masks::MaskBody,
        masks::ObjectRef,
        masks::MasksRequest,
        masks::ObjectMasksResponse,
        masks::MasksResponse,
        ops::HealthResponse,
        ops::ReadinessResponse,
        ops::ClusterWorkers,
    )),
    modifiers(&BearerAuth),
    security(("bearer" = [])),
)]
pub struct ApiDoc;

/// Declares the optional bearer-token scheme.
struct BearerAuth;

impl utoipa::Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

#[utoipa::path(get, path = "/v1/openapi.json", tag = "ops",
    responses((status = 200, description = "this document")))]
pub async fn openapi_json() -> Json<utoipa::openapi::OpenApi> {
    Json(ApiDoc::openapi())
}
