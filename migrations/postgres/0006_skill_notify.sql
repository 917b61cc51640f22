-- Several servers on one data base (issue 24): every change to `skills` is told to the other
-- servers, which keep in memory the k-nearest and recognition indexes and a cache of skills'
-- JSON (services/src/store/postgres/follow.rs listens).
--
-- A trigger rather than a `pg_notify` beside each write in the store's queries: it catches every
-- path that changes skills, today's (ingest, bulk ingest, delete skill, delete session,
-- reprocess) and tomorrow's, the `ON DELETE SET NULL` of `matched_skill_id` that changes the
-- skills matched to a deleted one, and SQL run by hand. NOTIFY is transactional: the message
-- goes out at the commit of the write, never for a rolled-back one, and in commit order.
--
-- Channel `icms_skills`, one per data base: the payload names the schema of the table, so that
-- stores in other schemas of the same data base (the tests' schemas) ignore it. Payload:
-- `{"schema": "public", "op": "INSERT" | "UPDATE" | "DELETE" | "TRUNCATE", "ids": [1, 2]}`,
-- the ids of the rows the statement changed, at most 300 a message: a NOTIFY payload must stay
-- under 8000 bytes, and 300 ids of 20 digits and a comma with the schema's 63 bytes do.
-- `TRUNCATE` names no ids: a listener reloads everything.
--
-- The skills of a reprocessed session whose rows stay the same still get an UPDATE (their
-- approach template is written again), so their cached JSON, which reports the session's
-- segmentation version, is dropped too.
CREATE FUNCTION icms_notify_skills() RETURNS trigger LANGUAGE plpgsql AS $$
DECLARE
    ids BIGINT[];
    n INTEGER;
    i INTEGER := 1;
BEGIN
    IF TG_OP = 'TRUNCATE' THEN
        PERFORM pg_notify('icms_skills',
            json_build_object('schema', TG_TABLE_SCHEMA, 'op', TG_OP)::text);
        RETURN NULL;
    ELSIF TG_OP = 'DELETE' THEN
        SELECT array_agg(id ORDER BY id) INTO ids FROM icms_old_skills;
    ELSE
        SELECT array_agg(id ORDER BY id) INTO ids FROM icms_new_skills;
    END IF;
    n := coalesce(array_length(ids, 1), 0);
    WHILE i <= n LOOP
        PERFORM pg_notify('icms_skills',
            json_build_object('schema', TG_TABLE_SCHEMA, 'op', TG_OP,
                'ids', ids[i:i + 299])::text);
        i := i + 300;
    END LOOP;
    RETURN NULL;
END
$$;

-- One trigger per event: a trigger with transition tables may have only one.
CREATE TRIGGER skills_notify_insert AFTER INSERT ON skills
    REFERENCING NEW TABLE AS icms_new_skills
    FOR EACH STATEMENT EXECUTE FUNCTION icms_notify_skills();
CREATE TRIGGER skills_notify_update AFTER UPDATE ON skills
    REFERENCING NEW TABLE AS icms_new_skills
    FOR EACH STATEMENT EXECUTE FUNCTION icms_notify_skills();
CREATE TRIGGER skills_notify_delete AFTER DELETE ON skills
    REFERENCING OLD TABLE AS icms_old_skills
    FOR EACH STATEMENT EXECUTE FUNCTION icms_notify_skills();
CREATE TRIGGER skills_notify_truncate AFTER TRUNCATE ON skills
    FOR EACH STATEMENT EXECUTE FUNCTION icms_notify_skills();
