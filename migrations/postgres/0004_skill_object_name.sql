-- Scenes of several objects (issue 19): PostgreSQL's copy of migrations/0004_skill_object_name.sql.
ALTER TABLE skills ADD COLUMN object_name TEXT COLLATE "C";
