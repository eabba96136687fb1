-- Workers register here and heartbeat, so every API process can show the cluster's workers
-- (issue 20 item 3): one row per worker slot, named like its lease owner.
CREATE TABLE workers (
    id TEXT PRIMARY KEY,
    instance TEXT NOT NULL,
    device TEXT NOT NULL,
    kinds_json TEXT NOT NULL,
    state TEXT NOT NULL,
    job_id TEXT,
    started_at_ms INTEGER NOT NULL,
    heartbeat_at_ms INTEGER NOT NULL
);
CREATE INDEX workers_heartbeat ON workers (heartbeat_at_ms);
