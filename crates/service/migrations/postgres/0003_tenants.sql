-- In step with ../sqlite/0003_tenants.sql: every scene and job belongs to a tenant.
ALTER TABLE scenes ADD COLUMN tenant TEXT NOT NULL DEFAULT 'default';
ALTER TABLE jobs ADD COLUMN tenant TEXT NOT NULL DEFAULT 'default';
CREATE INDEX scenes_tenant ON scenes (tenant, created_at_ms);
CREATE INDEX jobs_tenant ON jobs (tenant, created_at_ms);
