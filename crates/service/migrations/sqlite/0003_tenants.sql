-- Tenants (issue 19 item 14): every scene and job belongs to the tenant whose token created it
-- (a job to its scene's tenant). Rows from before tenants belong to the default tenant, which
-- is also the tenant of plain `auth.tokens`, so a service upgraded without tenant tokens sees
-- all its old data as before.
ALTER TABLE scenes ADD COLUMN tenant TEXT NOT NULL DEFAULT 'default';
ALTER TABLE jobs ADD COLUMN tenant TEXT NOT NULL DEFAULT 'default';
CREATE INDEX scenes_tenant ON scenes (tenant, created_at_ms);
CREATE INDEX jobs_tenant ON jobs (tenant, created_at_ms);
