//! Simulations and replays as jobs in the store (issue 24, work spread over machines): one job
//! per request, claims that never take a job twice, leases that give a dead worker's job to the
//! next worker, settling only by the claim that holds the job, cancelling, and the jobs going
//! with their results. Every test runs on SQLite and on PostgreSQL.

use crate::store_common;

use std::collections::HashSet;
use std::time::Duration;

use dfs_core::scenario::Scenario;
use services::store::{
    Job, JobEnd, JobError, JobRequest, JobResult, JobState, Renewal, Store, StoreError,
    MAX_JOB_ATTEMPTS, MAX_JOB_REQUEST_BYTES,
};
use store_common::{fake_mcap, meta, skills, Backend};

const LEASE: Duration = Duration::from_secs(30);

fn simulation(seed: u64) -> JobRequest {
    JobRequest::Simulation {
        scenario: Box::new(Scenario::builtin(Scenario::BUILTINS[0], seed).unwrap()),
        duration: None,
    }
}

async fn submit(store: &Store, request: &JobRequest) -> (Job, bool) {
    let s = store.submit_job(request, 1000).await.unwrap();
    (s.job, s.new)
}

async fn claim(store: &Store, worker: &str, lease: Duration) -> Job {
    store
        .claim_job(worker, lease)
        .await
        .unwrap()
        .unwrap_or_else(|| panic!("{worker} found no job to claim"))
}

async fn a_request_has_one_job_until_it_fails_or_is_cancelled(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let (a, new) = submit(&store, &simulation(1)).await;
    assert!(new);
    assert_eq!(a.state, JobState::Queued);
    assert_eq!((a.attempts, a.worker.as_deref()), (0, None));
    assert_eq!(
        a.request,
        simulation(1),
        "the request reads back as it went in"
    );
    // The same request finds the same job; another seed is another job.
    let (again, new) = submit(&store, &simulation(1)).await;
    assert!(!new);
    assert_eq!(again.id, a.id);
    let (b, new) = submit(&store, &simulation(2)).await;
    assert!(new && b.id != a.id);
    // Too many waiting: refused, nothing queued.
    let e = store.submit_job(&simulation(3), 2).await.unwrap_err();
    assert!(matches!(e, StoreError::QueueFull(2)), "{e}");
    assert!(e.to_string().contains("wait for a worker"), "{e}");
    assert_eq!(store.jobs(None, None, 100).await.unwrap().len(), 2);
    // A failed job is not reused: asking again makes a new one.
    let w = claim(&store, "w", LEASE).await;
    assert_eq!(w.id, a.id);
    let failure = JobEnd::Failed(JobError {
        status: 422,
        detail: "the simulation failed".into(),
    });
    assert!(store
        .settle_job(&w.claim().unwrap(), &failure)
        .await
        .unwrap());
    let failed = store.job(a.id).await.unwrap();
    assert_eq!(failed.state, JobState::Failed);
    assert_eq!(failed.error.as_ref().unwrap().status, 422);
    assert!(failed.finished_at.is_some());
    let (c, new) = submit(&store, &simulation(1)).await;
    assert!(new && c.id != a.id);
    // So is a cancelled one; cancelling a waiting job ends it at once.
    let cancelled = store.cancel_job(c.id).await.unwrap();
    assert_eq!(cancelled.state, JobState::Cancelled);
    let (d, new) = submit(&store, &simulation(1)).await;
    assert!(new && d.id != c.id);
    assert!(matches!(
        store.job(999_999).await,
        Err(StoreError::JobNotFound(999_999))
    ));
    assert!(matches!(
        store.cancel_job(999_999).await,
        Err(StoreError::JobNotFound(_))
    ));
}

async fn a_replay_job_goes_with_its_skill_and_a_done_job_with_its_result(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let out = store
        .ingest(&fake_mcap(1, 1000), meta(1, 2), skills(1, 2))
        .await
        .unwrap();
    let replay = |skill_id| JobRequest::Replay {
        skill_id,
        hand: "gripper".into(),
    };
    let e = store.submit_job(&replay(424_242), 10).await.unwrap_err();
    assert!(matches!(e, StoreError::SkillNotFound(424_242)), "{e}");
    let (r, _) = submit(&store, &replay(out.skill_ids[0])).await;
    store.delete_skill(out.skill_ids[0]).await.unwrap();
    assert!(
        matches!(store.job(r.id).await, Err(StoreError::JobNotFound(_))),
        "the replay job went with its skill"
    );
    // A simulation done with this session goes when the session goes: asking again runs it
    // again.
    let (s, _) = submit(&store, &simulation(5)).await;
    let held = claim(&store, "w", LEASE).await;
    assert_eq!(held.id, s.id);
    let result = JobResult::Session {
        id: out.session_id,
        created: true,
    };
    assert!(store
        .settle_job(&held.claim().unwrap(), &JobEnd::Done(result))
        .await
        .unwrap());
    let done = store.job(s.id).await.unwrap();
    assert_eq!((done.state, done.result), (JobState::Done, Some(result)));
    let (same, new) = submit(&store, &simulation(5)).await;
    assert!(!new && same.id == s.id && same.state == JobState::Done);
    store.delete_session(out.session_id).await.unwrap();
    assert!(matches!(
        store.job(s.id).await,
        Err(StoreError::JobNotFound(_))
    ));
    let (anew, new) = submit(&store, &simulation(5)).await;
    assert!(new && anew.id != s.id);
}

async fn only_the_claim_that_holds_a_job_renews_settles_or_gives_it_back(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let (a, _) = submit(&store, &simulation(1)).await;
    let (b, _) = submit(&store, &simulation(2)).await;
    // Oldest first, each to one worker.
    let ja = claim(&store, "host:1:0", LEASE).await;
    let jb = claim(&store, "host:2:0", LEASE).await;
    assert_eq!((ja.id, jb.id), (a.id, b.id));
    assert_eq!(ja.state, JobState::Running);
    assert_eq!((ja.attempts, ja.worker.as_deref()), (1, Some("host:1:0")));
    assert!(ja.started_at.is_some());
    assert!(store.claim_job("host:3:0", LEASE).await.unwrap().is_none());
    let ca = ja.claim().unwrap();
    assert_eq!(store.renew_job(&ca, LEASE).await.unwrap(), Renewal::Held);
    // Another worker's name, or another attempt, is not the claim.
    let mut wrong = ca.clone();
    wrong.worker = "host:2:0".into();
    assert_eq!(store.renew_job(&wrong, LEASE).await.unwrap(), Renewal::Lost);
    assert!(!store.settle_job(&wrong, &JobEnd::Cancelled).await.unwrap());
    let mut stale = ca.clone();
    stale.attempt = 2;
    assert!(!store.settle_job(&stale, &JobEnd::Released).await.unwrap());
    assert_eq!(store.job(a.id).await.unwrap().state, JobState::Running);
    // Given back (its worker shuts down): waiting again, the attempt not counted, and the next
    // claim takes it.
    assert!(store.settle_job(&ca, &JobEnd::Released).await.unwrap());
    let back = store.job(a.id).await.unwrap();
    assert_eq!((back.state, back.attempts), (JobState::Queued, 0));
    assert!(!store.settle_job(&ca, &JobEnd::Cancelled).await.unwrap());
    let again = claim(&store, "host:3:0", LEASE).await;
    assert_eq!((again.id, again.attempts), (a.id, 1));
    // Cancelling a running job asks its worker, whose next renewal hears it.
    let cb = jb.claim().unwrap();
    let asked = store.cancel_job(b.id).await.unwrap();
    assert_eq!(asked.state, JobState::Running);
    assert!(asked.cancel_requested);
    assert_eq!(
        store.renew_job(&cb, LEASE).await.unwrap(),
        Renewal::CancelRequested
    );
    assert!(store.settle_job(&cb, &JobEnd::Cancelled).await.unwrap());
    assert_eq!(store.job(b.id).await.unwrap().state, JobState::Cancelled);
    // A finished job stays as it is.
    assert_eq!(
        store.cancel_job(b.id).await.unwrap().state,
        JobState::Cancelled
    );
}

async fn a_dead_workers_job_is_claimed_again_and_failed_after_its_last_attempt(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let (a, _) = submit(&store, &simulation(1)).await;
    // Each worker "dies" at once: a lease of 0 ms runs out as soon as the clock moves.
    let mut claims = Vec::new();
    for attempt in 1..=MAX_JOB_ATTEMPTS {
        tokio::time::sleep(Duration::from_millis(20)).await;
        let j = claim(&store, &format!("w{attempt}"), Duration::ZERO).await;
        assert_eq!((j.id, j.attempts), (a.id, attempt));
        claims.push(j.claim().unwrap());
    }
    // The dead workers' claims are gone: none of them may renew or settle.
    for c in &claims[..claims.len() - 1] {
        assert_eq!(store.renew_job(c, LEASE).await.unwrap(), Renewal::Lost);
    }
    let first_end = JobEnd::Done(JobResult::Replay { id: 1 });
    assert!(!store.settle_job(&claims[0], &first_end).await.unwrap());
    // After the last attempt's lease: failed, not claimed a fourth time.
    tokio::time::sleep(Duration::from_millis(20)).await;
    assert!(store.claim_job("w4", LEASE).await.unwrap().is_none());
    let failed = store.job(a.id).await.unwrap();
    assert_eq!(failed.state, JobState::Failed);
    let e = failed.error.unwrap();
    assert_eq!(e.status, 503);
    assert!(
        e.detail.contains(&format!("{MAX_JOB_ATTEMPTS} times")),
        "{}",
        e.detail
    );
    // A job whose worker died while a cancel was asked for ends cancelled.
    let (b, _) = submit(&store, &simulation(2)).await;
    claim(&store, "w5", Duration::ZERO).await;
    store.cancel_job(b.id).await.unwrap();
    tokio::time::sleep(Duration::from_millis(20)).await;
    assert!(store.claim_job("w6", LEASE).await.unwrap().is_none());
    assert_eq!(store.job(b.id).await.unwrap().state, JobState::Cancelled);
}

async fn workers_claiming_at_once_never_take_the_same_job(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    const JOBS: u64 = 60;
    for seed in 0..JOBS {
        submit(&store, &simulation(seed)).await;
    }
    let mut tasks = tokio::task::JoinSet::new();
    for w in 0..6 {
        let store = store.clone();
        tasks.spawn(async move {
            let mut got = Vec::new();
            while let Some(j) = store.claim_job(&format!("w{w}"), LEASE).await.unwrap() {
                got.push(j.id);
            }
            got
        });
    }
    let mut all = Vec::new();
    while let Some(got) = tasks.join_next().await {
        all.extend(got.unwrap());
    }
    let distinct: HashSet<i64> = all.iter().copied().collect();
    assert_eq!(all.len(), JOBS as usize, "every job claimed once: {all:?}");
    assert_eq!(distinct.len(), JOBS as usize);
    let running = store
        .jobs(Some(JobState::Running), None, 200)
        .await
        .unwrap();
    assert_eq!(running.len(), JOBS as usize);
}

async fn jobs_are_listed_newest_first_by_state_a_page_at_a_time(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let mut ids = Vec::new();
    for seed in 0..5 {
        ids.push(submit(&store, &simulation(seed)).await.0.id);
    }
    store.cancel_job(ids[1]).await.unwrap();
    let page = store.jobs(None, None, 3).await.unwrap();
    let got: Vec<i64> = page.iter().map(|j| j.id).collect();
    assert_eq!(got, [ids[4], ids[3], ids[2]]);
    let rest = store.jobs(None, Some(ids[2]), 3).await.unwrap();
    let got: Vec<i64> = rest.iter().map(|j| j.id).collect();
    assert_eq!(got, [ids[1], ids[0]]);
    let cancelled = store
        .jobs(Some(JobState::Cancelled), None, 10)
        .await
        .unwrap();
    assert_eq!(cancelled.len(), 1);
    assert_eq!(cancelled[0].id, ids[1]);
    for bad in [0, 201] {
        assert!(matches!(
            store.jobs(None, None, bad).await,
            Err(StoreError::InvalidQuery(_))
        ));
    }
}

async fn the_same_request_submitted_at_once_makes_one_job(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let mut tasks = tokio::task::JoinSet::new();
    for _ in 0..8 {
        let store = store.clone();
        tasks.spawn(async move { store.submit_job(&simulation(3), 100).await.unwrap() });
    }
    let mut got = Vec::new();
    while let Some(s) = tasks.join_next().await {
        got.push(s.unwrap());
    }
    assert_eq!(got.iter().filter(|s| s.new).count(), 1, "{got:?}");
    assert!(got.iter().all(|s| s.job.id == got[0].job.id), "{got:?}");
    assert_eq!(store.jobs(None, None, 100).await.unwrap().len(), 1);
}

async fn a_request_too_large_to_keep_is_refused(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let mut scenario = Scenario::builtin(Scenario::BUILTINS[0], 1).unwrap();
    scenario.name = "x".repeat(MAX_JOB_REQUEST_BYTES);
    let request = JobRequest::Simulation {
        scenario: Box::new(scenario),
        duration: None,
    };
    let e = store.submit_job(&request, 100).await.unwrap_err();
    assert!(matches!(e, StoreError::InvalidInput(_)), "{e}");
    assert!(e.to_string().contains("bytes"), "{e}");
    assert!(store.jobs(None, None, 100).await.unwrap().is_empty());
}

async fn a_job_its_worker_cannot_read_is_failed_saying_so(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let (a, _) = submit(&store, &simulation(1)).await;
    let (b, _) = submit(&store, &simulation(2)).await;
    // A newer version's request, say: not a request this worker knows.
    backend
        .sql(
            tmp.path(),
            &[(
                r#"UPDATE jobs SET request = '{"kind": "teleport"}' WHERE id = ?"#,
                Some(a.id),
            )],
        )
        .await;
    assert!(store.claim_job("w", LEASE).await.unwrap().is_none());
    let failed = backend
        .count(
            tmp.path(),
            "SELECT COUNT(*) FROM jobs WHERE state = 'failed' AND error_status = 500 \
             AND error_detail LIKE '%cannot be read by the worker%'",
        )
        .await;
    assert_eq!(failed, 1);
    // The next claim takes the next job.
    assert_eq!(claim(&store, "w", LEASE).await.id, b.id);
}

async fn old_failed_and_cancelled_jobs_are_deleted_and_done_ones_kept(backend: Backend) {
    let tmp = tempfile::tempdir().unwrap();
    let store = backend.open(tmp.path()).await;
    let out = store
        .ingest(&fake_mcap(1, 1000), meta(1, 1), skills(1, 1))
        .await
        .unwrap();
    let mut ids = Vec::new();
    for seed in 0..4 {
        ids.push(submit(&store, &simulation(seed)).await.0.id);
    }
    // 0: cancelled long ago; 1: cancelled now; 2: failed long ago; 3: done long ago.
    store.cancel_job(ids[0]).await.unwrap();
    store.cancel_job(ids[1]).await.unwrap();
    for (id, end) in [
        (
            ids[2],
            JobEnd::Failed(JobError {
                status: 422,
                detail: "no".into(),
            }),
        ),
        (
            ids[3],
            JobEnd::Done(JobResult::Session {
                id: out.session_id,
                created: true,
            }),
        ),
    ] {
        let j = claim(&store, "w", LEASE).await;
        assert_eq!(j.id, id);
        assert!(store.settle_job(&j.claim().unwrap(), &end).await.unwrap());
    }
    for id in [ids[0], ids[2], ids[3]] {
        backend
            .sql(
                tmp.path(),
                &[(
                    "UPDATE jobs SET finished_at = '2020-01-01T00:00:00.000Z' WHERE id = ?",
                    Some(id),
                )],
            )
            .await;
    }
    let week = Duration::from_secs(7 * 24 * 3600);
    assert_eq!(store.prune_jobs(week).await.unwrap(), 2);
    let left: Vec<i64> = store
        .jobs(None, None, 100)
        .await
        .unwrap()
        .iter()
        .map(|j| j.id)
        .collect();
    assert_eq!(left, [ids[3], ids[1]]);
    assert_eq!(store.prune_jobs(week).await.unwrap(), 0);
}

backend_tests!(
    the_same_request_submitted_at_once_makes_one_job,
    a_request_too_large_to_keep_is_refused,
    a_job_its_worker_cannot_read_is_failed_saying_so,
    old_failed_and_cancelled_jobs_are_deleted_and_done_ones_kept,
    a_request_has_one_job_until_it_fails_or_is_cancelled,
    a_replay_job_goes_with_its_skill_and_a_done_job_with_its_result,
    only_the_claim_that_holds_a_job_renews_settles_or_gives_it_back,
    a_dead_workers_job_is_claimed_again_and_failed_after_its_last_attempt,
    workers_claiming_at_once_never_take_the_same_job,
    jobs_are_listed_newest_first_by_state_a_page_at_a_time,
);
