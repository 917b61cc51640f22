// The API from the page: JSON in and out, every error an RFC 9457 problem shown with its
// title and detail.

/** An error answer of the API: its status, title and detail. */
export class ApiError extends Error {
  constructor(status, title, detail) {
    super(`${title}: ${detail}`);
    this.status = status;
    this.title = title;
    this.detail = detail;
  }
}

/** Reads a problem (or whatever came) from an error response. */
async function problemOf(r) {
  let title = r.statusText || `HTTP ${r.status}`;
  let detail = '';
  try {
    const body = await r.json();
    if (body && typeof body === 'object') {
      title = typeof body.title === 'string' ? body.title : title;
      detail = typeof body.detail === 'string' ? body.detail : '';
    }
  } catch {
    detail = 'the server answered an error without a problem document';
  }
  return new ApiError(r.status, title, detail);
}

/** GET (or `init`) `path` → parsed JSON; throws ApiError on an error status. */
export async function api(path, init) {
  let r;
  try {
    r = await fetch(path, init);
  } catch (e) {
    throw new ApiError(0, 'The server does not answer', String(e.message ?? e));
  }
  if (!r.ok) throw await problemOf(r);
  if (r.status === 204) return null;
  return r.json();
}

/** POST `body` as JSON to `path`. */
export function post(path, body) {
  return api(path, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify(body),
  });
}

/**
 * POST `body` to `path`, an endpoint that runs a job (a simulation, a replay): its result.
 * A job not finished within the server's wait is answered 202 with the job; it is then read
 * every half second (`onWaiting(job)` told each time) until done, and its result read, or
 * until it failed or was cancelled (thrown as the ApiError the request would have got).
 */
export async function postJob(path, body, onWaiting) {
  let r;
  try {
    r = await fetch(path, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify(body),
    });
  } catch (e) {
    throw new ApiError(0, 'The server does not answer', String(e.message ?? e));
  }
  if (!r.ok) throw await problemOf(r);
  if (r.status !== 202) return r.json();
  let job = await r.json();
  for (;;) {
    if (job.state === 'done') return api(job.result_url);
    if (job.state === 'failed') {
      const e = job.error ?? {};
      throw new ApiError(e.status ?? 500, e.title ?? 'Failed', e.detail ?? `job ${job.job_id} failed`);
    }
    if (job.state === 'cancelled') {
      throw new ApiError(409, 'Cancelled', `job ${job.job_id} was cancelled before it finished`);
    }
    if (onWaiting) onWaiting(job);
    await new Promise(resolve => setTimeout(resolve, 500));
    job = await api(job.url);
  }
}

/** A query string of the non-empty entries of `params`. */
export function query(params) {
  const q = new URLSearchParams();
  for (const [k, v] of Object.entries(params)) {
    if (v !== undefined && v !== null && v !== '') q.set(k, v);
  }
  const s = q.toString();
  return s ? `?${s}` : '';
}

/** Shows an error (an ApiError's title and detail) in the page's error bar. */
export function showError(e) {
  const bar = document.getElementById('error');
  const title = e instanceof ApiError ? e.title : 'Error';
  const detail = e instanceof ApiError ? e.detail : String(e?.message ?? e);
  document.getElementById('error-title').textContent = title;
  document.getElementById('error-detail').textContent = detail;
  bar.hidden = false;
}

export function clearError() {
  document.getElementById('error').hidden = true;
}
