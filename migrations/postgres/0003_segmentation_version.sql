-- Reprocessing (issue 18): PostgreSQL's copy of migrations/0003_segmentation_version.sql.
ALTER TABLE sessions ADD COLUMN segmentation_version BIGINT NOT NULL DEFAULT 0
    CHECK (segmentation_version >= 0);
CREATE INDEX sessions_segmentation_version ON sessions (segmentation_version);
