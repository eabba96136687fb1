-- Blob prefixes that must be removed but could not be when it was decided (a failed upload's
-- files while the blob store was down, issue 39): swept at start and every few seconds while
-- any are left, until the store takes the deletion.
CREATE TABLE blob_deletions (
    prefix TEXT PRIMARY KEY,
    reason TEXT NOT NULL,
    recorded_at_ms INTEGER NOT NULL,
    last_error TEXT
);
