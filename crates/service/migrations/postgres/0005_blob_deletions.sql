-- In step with ../sqlite/0005_blob_deletions.sql: blob prefixes that must be removed but could
-- not be when it was decided, swept until the blob store takes the deletion.
CREATE TABLE blob_deletions (
    prefix TEXT PRIMARY KEY,
    reason TEXT NOT NULL,
    recorded_at_ms BIGINT NOT NULL,
    last_error TEXT
);
