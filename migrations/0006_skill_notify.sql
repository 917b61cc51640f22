-- Several servers on one data base (issue 24): nothing to do on SQLite, where one process
-- writes a data directory (icms.lock) and its caches follow its own writes. The version keeps
-- the two migration folders in step: PostgreSQL's 0006 adds the trigger that tells every
-- server of a change to `skills` (migrations/postgres/0006_skill_notify.sql).
SELECT 1;
