-- Simulations and replays as jobs (issue 24: work spread over machines). A request to simulate
-- a scenario or to replay a skill on a hand becomes a row here; a worker (any `icms serve`, or
-- `icms worker`) claims it, runs it, stores its result (a session, a replay) and marks it done.
-- The HTTP request waits a short while for that and otherwise answers 202 with the job's URL.
-- PostgreSQL's copy is migrations/postgres/0007_jobs.sql; services/src/store/jobs.rs reads
-- and writes these rows.
--
-- A job's claim is its `worker` and `attempts` together: a worker keeps its lease
-- (`lease_until_ms`, the data base's clock in ms since 1970) renewed while it runs the job;
-- a job whose lease ran out (its worker died) is claimed again by the next free worker, at most
-- a few times, then failed. Only the claim that holds it may finish, fail or give back a job.
--
-- `request_key` is the hex SHA-256 of the job's kind and its canonical request: the same
-- request while its job waits, runs or after it is done answers with that job (a job that
-- failed or was cancelled is not reused: asking again runs the work again). A job goes with its
-- result, and a replay job with its skill (ON DELETE CASCADE): once the session, replay or skill
-- is deleted, the same request runs again. Failed and cancelled jobs are deleted a week after
-- they ended (the server's hourly sweep). A request is at most 64 KiB as stored.
CREATE TABLE jobs (
    id               INTEGER PRIMARY KEY AUTOINCREMENT,
    kind             TEXT    NOT NULL CHECK (kind IN ('simulation', 'replay')),
    request_key      TEXT    NOT NULL,
    request          TEXT    NOT NULL,   -- what the worker runs, JSON
    skill_id         INTEGER REFERENCES skills (id) ON DELETE CASCADE,
    state            TEXT    NOT NULL DEFAULT 'queued'
        CHECK (state IN ('queued', 'running', 'done', 'failed', 'cancelled')),
    cancel_requested INTEGER NOT NULL DEFAULT 0 CHECK (cancel_requested IN (0, 1)),
    attempts         INTEGER NOT NULL DEFAULT 0,
    worker           TEXT,
    lease_until_ms   INTEGER,
    session_id       INTEGER REFERENCES sessions (id) ON DELETE CASCADE,
    session_created  INTEGER CHECK (session_created IN (0, 1)),
    replay_id        INTEGER REFERENCES replays (id) ON DELETE CASCADE,
    error_status     INTEGER,
    error_detail     TEXT,
    created_at       TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    started_at       TEXT,
    finished_at      TEXT
);
-- One waiting, running or done job per request.
CREATE UNIQUE INDEX jobs_request ON jobs (request_key)
    WHERE state IN ('queued', 'running', 'done');
-- What workers look through for a job to claim, the queue's length, the lists by state, and
-- the pruning of old failed and cancelled jobs. (A partial index over the open states would
-- not serve `state = 'queued'`: SQLite does not prove one IN list from an equality.)
CREATE INDEX jobs_state ON jobs (state, id);
-- The cascades from deleted rows.
CREATE INDEX jobs_skill ON jobs (skill_id);
CREATE INDEX jobs_session ON jobs (session_id);
CREATE INDEX jobs_replay ON jobs (replay_id);
