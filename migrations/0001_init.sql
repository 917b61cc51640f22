-- ICMS skill data base, first schema.
--
-- Marks the file as ours: application_id 0x49434D53 ('ICMS'). Store::open refuses a database
-- with another non-zero application_id, or with tables but no marker.
PRAGMA application_id = 1229147475;

-- One recorded grasp session. Its MCAP bytes live in a content-addressed blob under the data
-- directory (blob_path, relative to it), written and fsynced before this row commits.
CREATE TABLE sessions (
    id           INTEGER PRIMARY KEY AUTOINCREMENT,
    sha256       TEXT    NOT NULL,            -- hex SHA-256 of the MCAP bytes
    size_bytes   INTEGER NOT NULL,
    blob_path    TEXT    NOT NULL,
    scenario     TEXT,
    hand         TEXT    NOT NULL,
    object_shape TEXT    NOT NULL,
    duration_ns  INTEGER NOT NULL,
    meta         TEXT    NOT NULL,            -- SessionMeta as JSON
    created_at   TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
-- Idempotent ingest: the same bytes never make two sessions, even under concurrent ingests.
CREATE UNIQUE INDEX sessions_sha256 ON sessions (sha256);

-- One skill: the hand-independent parameters of one grasp found in a session.
CREATE TABLE skills (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    session_id      INTEGER NOT NULL REFERENCES sessions (id) ON DELETE CASCADE,
    object_shape    TEXT    NOT NULL,
    object_mass     REAL    NOT NULL,         -- kg
    mu              REAL    NOT NULL,         -- Coulomb friction coefficient
    contact_count   INTEGER NOT NULL,
    contact_model   TEXT    NOT NULL,
    grasp_type      TEXT    NOT NULL,
    quality         REAL    NOT NULL,         -- Ferrari-Canny epsilon
    volume          REAL    NOT NULL,         -- GWS volume metric
    duration_s      REAL    NOT NULL,         -- s
    start_ns        INTEGER NOT NULL,         -- ns since session start
    end_ns          INTEGER NOT NULL,
    phase_durations TEXT    NOT NULL,         -- [[name, seconds], ...] as JSON (read path)
    feature         BLOB    NOT NULL,         -- FEATURE_DIM little-endian f32
    params          TEXT    NOT NULL,         -- full parameters as JSON
    created_at      TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
CREATE INDEX skills_session ON skills (session_id);
-- One index per filter (SQLite appends the rowid, so each also serves keyset order on (col, id)).
CREATE INDEX skills_mass ON skills (object_mass);
CREATE INDEX skills_mu ON skills (mu);
CREATE INDEX skills_contact_count ON skills (contact_count);
CREATE INDEX skills_contact_model ON skills (contact_model);
CREATE INDEX skills_quality ON skills (quality);
CREATE INDEX skills_duration ON skills (duration_s);
-- Equality filter + sort: the common browse queries.
-- (mass rides along so the common shape + mass window + best-quality query filters in the index)
CREATE INDEX skills_shape_quality ON skills (object_shape, quality, object_mass);
CREATE INDEX skills_shape_mass ON skills (object_shape, object_mass);
CREATE INDEX skills_grasp_quality ON skills (grasp_type, quality);

-- Phase durations of a skill, one row per phase, for the phase-duration filter.
CREATE TABLE skill_phases (
    skill_id   INTEGER NOT NULL REFERENCES skills (id) ON DELETE CASCADE,
    ord        INTEGER NOT NULL,              -- position of the phase in the skill
    name       TEXT    NOT NULL,
    duration_s REAL    NOT NULL,              -- s
    PRIMARY KEY (skill_id, ord)
) WITHOUT ROWID;
CREATE INDEX skill_phases_name_duration ON skill_phases (name, duration_s);
