-- In step with ../sqlite/0002_lease_expiries.sql: lease expiries after a new checkpoint are
-- counted apart from attempts, against their own bound.
ALTER TABLE jobs ADD COLUMN lease_expiries BIGINT NOT NULL DEFAULT 0;
ALTER TABLE jobs ADD COLUMN max_lease_expiries BIGINT NOT NULL DEFAULT 10;
ALTER TABLE jobs ADD COLUMN checkpointed_this_attempt BOOLEAN NOT NULL DEFAULT FALSE;
