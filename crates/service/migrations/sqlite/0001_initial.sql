-- segsplat schema v1. Portable SQL (SQLite now, Postgres later): TEXT UUID ids, integer
-- millisecond timestamps, JSON as TEXT, vectors as little-endian f32 BLOBs.

CREATE TABLE scenes (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    format TEXT NOT NULL,
    frame_count INTEGER NOT NULL,
    sparse_point_count BIGINT NOT NULL,
    summary_json TEXT NOT NULL,
    blob_prefix TEXT NOT NULL,
    created_at_ms BIGINT NOT NULL
);

CREATE TABLE jobs (
    id TEXT PRIMARY KEY,
    scene_id TEXT NOT NULL REFERENCES scenes (id),
    kind TEXT NOT NULL,
    state TEXT NOT NULL,
    config_json TEXT NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0,
    max_attempts INTEGER NOT NULL,
    lease_owner TEXT,
    lease_expires_at_ms BIGINT,
    cancel_requested BOOLEAN NOT NULL DEFAULT FALSE,
    error TEXT,
    progress_json TEXT,
    created_at_ms BIGINT NOT NULL,
    updated_at_ms BIGINT NOT NULL,
    started_at_ms BIGINT,
    finished_at_ms BIGINT
);

CREATE INDEX jobs_state_created ON jobs (state, created_at_ms);
CREATE INDEX jobs_scene ON jobs (scene_id);

CREATE TABLE job_events (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id TEXT NOT NULL REFERENCES jobs (id),
    at_ms BIGINT NOT NULL,
    kind TEXT NOT NULL,
    payload_json TEXT NOT NULL
);

CREATE INDEX job_events_job ON job_events (job_id, id);

CREATE TABLE objects (
    scene_id TEXT NOT NULL REFERENCES scenes (id),
    level TEXT NOT NULL,
    object_id INTEGER NOT NULL,
    gaussian_count BIGINT NOT NULL,
    centroid_x REAL NOT NULL,
    centroid_y REAL NOT NULL,
    centroid_z REAL NOT NULL,
    bounds_min_x REAL NOT NULL,
    bounds_min_y REAL NOT NULL,
    bounds_min_z REAL NOT NULL,
    bounds_max_x REAL NOT NULL,
    bounds_max_y REAL NOT NULL,
    bounds_max_z REAL NOT NULL,
    mean_color_r REAL NOT NULL,
    mean_color_g REAL NOT NULL,
    mean_color_b REAL NOT NULL,
    PRIMARY KEY (scene_id, level, object_id)
);

CREATE TABLE object_embeddings (
    scene_id TEXT NOT NULL REFERENCES scenes (id),
    level TEXT NOT NULL,
    object_id INTEGER NOT NULL,
    model_id TEXT NOT NULL,
    dim INTEGER NOT NULL,
    vector BLOB NOT NULL,
    PRIMARY KEY (scene_id, level, object_id, model_id)
);
