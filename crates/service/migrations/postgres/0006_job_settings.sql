-- In step with ../sqlite/0006_job_settings.sql: the settings a job's worker resolved.
ALTER TABLE jobs ADD COLUMN settings_json TEXT;
