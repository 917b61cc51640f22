-- Robot hands uploaded by users, and replays of skills on hands.

-- One uploaded robot hand: a URDF plus a hand spec, validated by building the hand model before
-- the row is written. The built-in hands (glove10, allegro, barrett, inspire, gripper) are not
-- rows: they live in the binary and are listed from code beside these, so a new binary's
-- built-ins never disagree with a stale copy here. A hand's id is its name (URL-safe, unique
-- among built-in and uploaded hands); hands are never changed or deleted once stored, so a
-- replay naming one always finds it.
CREATE TABLE hands (
    id               INTEGER PRIMARY KEY AUTOINCREMENT,
    name             TEXT    NOT NULL UNIQUE,
    spec             TEXT    NOT NULL,        -- the hand spec as JSON
    urdf             TEXT    NOT NULL,        -- the URDF text
    dof              INTEGER NOT NULL,        -- independent joints of the model
    fingers          TEXT    NOT NULL,        -- fingertip names, the thumb first, as JSON
    dof_names        TEXT    NOT NULL,        -- DOF names in θ order, as JSON
    torque_limit_min REAL    NOT NULL,        -- N·m (N for prismatic DOFs)
    torque_limit_max REAL    NOT NULL,
    created_at       TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

-- One replay of a skill on a hand: its report and its MCAP recording (a content-addressed blob
-- like a session's, written and fsynced before this row commits). `hand` is the hand's name:
-- a built-in hand or a row of `hands` (no foreign key, since built-ins are not rows).
CREATE TABLE replays (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    skill_id       INTEGER NOT NULL REFERENCES skills (id) ON DELETE CASCADE,
    hand           TEXT    NOT NULL,
    success        INTEGER NOT NULL CHECK (success IN (0, 1)),
    failure_reason TEXT,                      -- unreachable, torque_limit, slip, no_force_closure
    report         TEXT    NOT NULL,          -- the replay report as JSON
    sha256         TEXT    NOT NULL,          -- hex SHA-256 of the MCAP bytes
    size_bytes     INTEGER NOT NULL,
    blob_path      TEXT    NOT NULL,
    created_at     TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
CREATE INDEX replays_skill ON replays (skill_id);
CREATE INDEX replays_hand ON replays (hand);
-- Deletes check whether another row (replay or session) still names a blob before unlinking it.
CREATE INDEX replays_sha256 ON replays (sha256);
