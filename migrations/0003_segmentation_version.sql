-- Reprocessing (issue 18): the version of the segmentation that made a session's skills
-- (services::segmentation::SEGMENTATION_VERSION when they were stored or last reprocessed).
--
-- Recorded per session, not per skill: a session's skills are always made together, from its
-- whole file, and replaced together (`icms reprocess`, one transaction per session), so they
-- share one version, and a session in which a segmentation found no grasp still records which
-- segmentation found none (a later one may find some). A skill reports its session's version.
--
-- Sessions stored before this migration get 0, "not recorded": which code segmented them is
-- not known, so `icms reprocess` checks them against the current segmentation (skills that
-- come out the same are kept, with their ids and replays).
ALTER TABLE sessions ADD COLUMN segmentation_version INTEGER NOT NULL DEFAULT 0
    CHECK (segmentation_version >= 0);
-- `icms reprocess` looks for the sessions below the current version.
CREATE INDEX sessions_segmentation_version ON sessions (segmentation_version);
