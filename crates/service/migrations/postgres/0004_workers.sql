-- In step with ../sqlite/0004_workers.sql: workers register and heartbeat here, one row per
-- worker slot, named like its lease owner.
CREATE TABLE workers (
    id TEXT PRIMARY KEY,
    instance TEXT NOT NULL,
    device TEXT NOT NULL,
    kinds_json TEXT NOT NULL,
    state TEXT NOT NULL,
    job_id TEXT,
    started_at_ms BIGINT NOT NULL,
    heartbeat_at_ms BIGINT NOT NULL
);
CREATE INDEX workers_heartbeat ON workers (heartbeat_at_ms);
