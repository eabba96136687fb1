-- The settings a job runs with, as its worker resolved them from the scene (steps, objects per
-- level, background, mask source): `config_json` keeps what the job was created with (issue 41).
ALTER TABLE jobs ADD COLUMN settings_json TEXT;
