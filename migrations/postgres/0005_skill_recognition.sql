-- The assistant (issue 20): PostgreSQL's copy of migrations/0005_skill_recognition.sql.
ALTER TABLE skills ADD COLUMN approach BYTEA;
ALTER TABLE skills ADD COLUMN matched_skill_id BIGINT REFERENCES skills (id) ON DELETE SET NULL;
-- ON DELETE SET NULL looks the referencing rows up: SQLite scans, PostgreSQL wants an index.
CREATE INDEX skills_matched ON skills (matched_skill_id);
