-- Lease expiries after which the job had saved a newer checkpoint are counted apart from
-- attempts (a crash of the process is not the job's fault when the job was making progress),
-- against their own, larger bound so a job that crashes its worker every time still ends.
ALTER TABLE jobs ADD COLUMN lease_expiries INTEGER NOT NULL DEFAULT 0;
ALTER TABLE jobs ADD COLUMN max_lease_expiries INTEGER NOT NULL DEFAULT 10;
-- Set when the lease holder saves a checkpoint; cleared by every claim.
ALTER TABLE jobs ADD COLUMN checkpointed_this_attempt BOOLEAN NOT NULL DEFAULT FALSE;
