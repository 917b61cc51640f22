// The ICMS web page: a hash router over a few views, each built from the API's JSON with
// textContent only (dom.js), errors shown with the problem's title and detail (api.js).
import { api, post, postJob, query, showError, clearError, ApiError } from './api.js';
import { h, replace, fmt, facts } from './dom.js';

const main = document.getElementById('main');
/** Timings and counters the browser tests read (window.icms). */
const icms = (window.icms = { ready: null, listRenderedAt: null, frames: 0, fps: null });
let cleanup = [];

const SHAPES = ['sphere', 'box', 'cylinder', 'unknown'];
const CONTACT_MODELS = ['frictionless', 'point_with_friction', 'soft_finger'];
const PHASES = ['approach', 'preshape', 'grasp', 'lift', 'hold', 'transport', 'place', 'release', 'retreat'];
const SORTS = [['id', 'id ↑'], ['-id', 'id ↓'], ['-quality', 'quality ↓'], ['quality', 'quality ↑'],
  ['mass', 'mass ↑'], ['-mass', 'mass ↓'], ['duration', 'duration ↑'], ['-duration', 'duration ↓']];
const FILTERS = ['shape', 'mass_min', 'mass_max', 'mu_min', 'mu_max', 'contacts', 'contact_model',
  'grasp_type', 'min_quality', 'phase', 'phase_min_s', 'phase_max_s', 'sort', 'limit'];
const PHASE_COLOURS = { approach: '#cfe0f3', preshape: '#d9d2f0', grasp: '#f6d5b5', lift: '#c8ecc4',
  hold: '#a8dca2', transport: '#e8f0a6', place: '#f3c6c6', release: '#f0e0c8', retreat: '#e3e3e3' };

function setReady(name) {
  icms.ready = name;
  document.body.dataset.ready = name;
}

async function route() {
  for (const f of cleanup.splice(0)) f();
  clearError();
  icms.ready = null;
  delete document.body.dataset.ready;
  const hash = location.hash || '#/skills';
  const [path, qs] = hash.slice(1).split('?');
  const params = new URLSearchParams(qs ?? '');
  const parts = path.split('/').filter(Boolean);
  for (const a of document.querySelectorAll('header a[data-nav]')) {
    a.classList.toggle('active', a.dataset.nav === parts[0]);
  }
  try {
    if (parts[0] === 'skills' && parts[1]) await skillView(parts[1]);
    else if (parts[0] === 'sessions' && parts[1]) await sessionView(parts[1]);
    else if (parts[0] === 'sessions') await sessionsView(params);
    else if (parts[0] === 'hands') await handsView();
    else if (parts[0] === 'skills' || parts.length === 0) await skillsView(params);
    else {
      replace(main, h('h1', { id: 'not-found' }, 'Page not found'),
        h('p', {}, 'No view at ', h('code', {}, hash), '. ', h('a', { href: '#/skills' }, 'The skills.')));
      setReady('not-found');
    }
  } catch (e) {
    showError(e);
    setReady('error');
  }
}

// ---------------------------------------------------------------- the skill list

function filterForm(params) {
  const input = (name, label, attrs = {}) => h('label', {}, label,
    h('input', { name, value: params.get(name) ?? '', inputmode: 'decimal', ...attrs }));
  const select = (name, label, options) => h('label', {}, label,
    h('select', { name }, h('option', { value: '' }, 'any'),
      options.map(o => {
        const [v, text] = Array.isArray(o) ? o : [o, o];
        return h('option', { value: v, selected: params.get(name) === v }, text);
      })));
  const sort = h('label', {}, 'sort', h('select', { name: 'sort' },
    SORTS.map(([v, t]) => h('option', { value: v, selected: (params.get('sort') ?? 'id') === v }, t))));
  const limit = h('label', {}, 'per page', h('select', { name: 'limit' },
    ['25', '50', '100', '200'].map(v => h('option', { value: v, selected: (params.get('limit') ?? '50') === v }, v))));
  const form = h('form', { class: 'filters', id: 'filters' },
    select('shape', 'shape', SHAPES),
    input('mass_min', 'mass ≥ (kg)'), input('mass_max', 'mass ≤ (kg)'),
    input('mu_min', 'μ ≥'), input('mu_max', 'μ ≤'),
    input('contacts', 'contacts', { inputmode: 'numeric' }),
    select('contact_model', 'contact model', CONTACT_MODELS),
    input('grasp_type', 'grasp type', { inputmode: 'text', placeholder: 'precision' }),
    input('min_quality', 'quality ε ≥'),
    select('phase', 'phase', PHASES),
    input('phase_min_s', 'phase ≥ (s)'), input('phase_max_s', 'phase ≤ (s)'),
    sort, limit,
    h('button', { type: 'submit', id: 'apply' }, 'Apply'),
    h('button', { type: 'reset', id: 'reset' }, 'Clear'));
  form.addEventListener('submit', e => {
    e.preventDefault();
    const q = {};
    for (const name of FILTERS) {
      const v = form.elements[name].value.trim();
      if (v !== '' && !(name === 'sort' && v === 'id') && !(name === 'limit' && v === '50')) q[name] = v;
    }
    location.hash = `#/skills${query(q)}`;
  });
  form.addEventListener('reset', e => { e.preventDefault(); location.hash = '#/skills'; });
  return form;
}

async function skillsView(params) {
  const filters = {};
  for (const name of FILTERS) if (params.get(name)) filters[name] = params.get(name);
  const cursors = (params.get('after') ?? '').split(',').filter(Boolean);
  const cursor = cursors.at(-1);
  const tbody = h('tbody', { id: 'skill-rows' });
  const status = h('span', { id: 'page-status' }, 'Loading…');
  const prev = h('button', { type: 'button', id: 'prev', disabled: cursors.length === 0 }, '← Previous');
  const next = h('button', { type: 'button', id: 'next', disabled: true }, 'Next →');
  replace(main, h('h1', {}, 'Skills'), filterForm(params),
    h('table', { id: 'skills' },
      h('thead', {}, h('tr', {}, h('th', { class: 'num' }, 'id'), h('th', {}, 'object'), h('th', {}, 'grasp type'),
        h('th', { class: 'num' }, 'contacts'), h('th', { class: 'num' }, 'quality ε'),
        h('th', { class: 'num' }, 'duration (s)'), h('th', { class: 'num' }, 'mass (kg)'), h('th', { class: 'num' }, 'μ'),
        h('th', {}, 'contact model'), h('th', { class: 'num' }, 'session'))),
      tbody),
    h('div', { class: 'pager' }, prev, next, status));
  const page = await api(`/api/v1/skills/summaries${query({ ...filters, cursor })}`);
  replace(tbody, page.items.map(s => h('tr', { dataset: { id: s.id } },
    h('td', { class: 'num' }, h('a', { href: `#/skills/${s.id}` }, String(s.id))),
    h('td', { class: 'object' }, s.object_name ? `${s.object_shape} “${s.object_name}”` : s.object_shape),
    h('td', {}, s.grasp_type),
    h('td', { class: 'num' }, String(s.contact_count)),
    h('td', { class: 'num' }, fmt(s.quality, 4)),
    h('td', { class: 'num' }, fmt(s.duration_s, 3)),
    h('td', { class: 'num' }, fmt(s.object_mass, 3)),
    h('td', { class: 'num' }, fmt(s.mu, 2)),
    h('td', {}, s.contact_model),
    h('td', { class: 'num' }, h('a', { href: `#/sessions/${s.session_id}` }, String(s.session_id))))));
  status.textContent = page.items.length
    ? `page ${cursors.length + 1}: ${page.items.length} skills${page.next_cursor ? '' : ' (last page)'}`
    : 'No skill matches these filters.';
  const go = list => {
    const q = { ...filters };
    if (list.length) q.after = list.join(',');
    location.hash = `#/skills${query(q)}`;
  };
  if (page.next_cursor) {
    next.disabled = false;
    next.addEventListener('click', () => go([...cursors, page.next_cursor]));
  }
  prev.addEventListener('click', () => go(cursors.slice(0, -1)));
  icms.listRenderedAt = performance.now();
  setReady('skills');
}

// ---------------------------------------------------------------- one skill

function phaseTimeline(skill) {
  const phases = skill.params?.phases ?? [];
  const start = skill.start_ns;
  const span = Math.max(1, skill.end_ns - start);
  return h('div', { class: 'timeline', id: 'timeline' }, phases.map(p => {
    const w = (100 * (p.end_ns - p.start_ns)) / span;
    const secs = (p.end_ns - p.start_ns) / 1e9;
    return h('div', {
      style: `width:${w.toFixed(3)}%;background:${PHASE_COLOURS[p.name] ?? '#ddd'}`,
      title: `${p.name}: ${secs.toFixed(3)} s`,
    }, p.name);
  }));
}

async function skillView(idText) {
  const id = Number(idText);
  if (!Number.isInteger(id)) throw new ApiError(400, 'Bad Request', `skill id ${JSON.stringify(idText)} is not an integer`);
  const skill = await api(`/api/v1/skills/${id}`);
  const p = skill.params ?? {};
  const src = p.source ?? {};
  const forcesBox = h('div', { id: 'forces' }, h('p', {}, 'Loading the contact forces…'));
  const contactsBox = h('div', { id: 'contacts3d' });
  const similarBox = h('div', { id: 'similar' }, h('p', {}, 'Loading…'));
  const replayBox = h('div', { id: 'replays' });
  replace(main,
    h('p', {}, h('a', { href: '#/skills' }, '← all skills')),
    h('h1', { id: 'skill-title' }, `Skill ${skill.id}: `, skill.grasp_type, ' on ', skill.object_name ? `${skill.object_shape} “${skill.object_name}”` : skill.object_shape),
    h('div', { class: 'cards' },
      h('section', { class: 'card' }, h('h2', {}, 'Grasp'), facts([
        ['grasp type', skill.grasp_type],
        ['contacts', `${skill.contact_count} (${skill.contact_model})`],
        ['quality ε (Ferrari-Canny)', fmt(skill.quality, 4)],
        ['force closure', String(p.quality?.force_closure ?? '—')],
        ['GWS volume', fmt(skill.volume, 4)],
        ['internal force', `${fmt(p.internal_force_n, 2)} N`],
        ['friction margin', `${fmt(p.friction_margin_n, 2)} N (${fmt(p.friction_margin_ratio, 2)})`],
        ['object', `${skill.object_shape}, ${fmt(skill.object_mass, 3)} kg, μ ${fmt(skill.mu, 2)}`],
        ['duration', `${fmt(skill.duration_s, 3)} s`],
        // The API lists them alphabetically; a grasp's phases read in their order.
        ['phases', [...skill.phase_durations].sort((a, b) => PHASES.indexOf(a.phase) - PHASES.indexOf(b.phase))
          .map(d => `${d.phase} ${fmt(d.seconds, 3)} s`).join(', ')],
        ['segmentation version', String(skill.segmentation_version)],
      ])),
      h('section', { class: 'card' }, h('h2', {}, 'Source session'), facts([
        ['session', h('a', { href: `#/sessions/${skill.session_id}`, class: 'session-link' }, `#${skill.session_id}`)],
        ['scenario', src.scenario ?? '—'],
        ['seed', src.seed === undefined ? '—' : String(src.seed)],
        ['hand', src.metadata?.hand ?? '—'],
        ['span', `${fmt(skill.start_ns / 1e9, 3)}–${fmt(skill.end_ns / 1e9, 3)} s`],
        ['file', h('a', { href: `/api/v1/sessions/${skill.session_id}/mcap`, download: '' }, 'download MCAP')],
      ])),
      h('section', { class: 'card' }, h('h2', {}, 'Contacts on the object'), contactsBox)),
    h('h2', {}, 'Phases'), phaseTimeline(skill),
    h('h2', {}, 'Contact forces'), forcesBox,
    h('h2', {}, 'Replay on a robot hand'), replayBox,
    h('h2', {}, 'Nearest skills'), similarBox);
  const jobs = [
    drawContacts(contactsBox, p).catch(e => { replace(contactsBox, h('p', { class: 'bad' }, `3D view unavailable: ${e.message ?? e}`)); }),
    drawForces(forcesBox, skill),
    drawSimilar(similarBox, id),
    replaysPanel(replayBox, skill),
  ];
  const results = await Promise.allSettled(jobs);
  for (const r of results) if (r.status === 'rejected') showError(r.reason);
  setReady('skill');
}

async function drawContacts(box, p) {
  const { View, objectMesh, contactMarker } = await import('./scene.js');
  const size = p.object?.size ?? [0.04];
  const view = new View(box, Math.max(...size, 0.03));
  cleanup.push(() => view.dispose());
  view.scene.add(objectMesh(p.object?.shape, size));
  for (const c of p.contacts ?? []) view.scene.add(contactMarker(c.position_b, c.normal_b));
  view.render();
  box.appendChild(h('p', {}, (p.contacts ?? []).map(c => `${c.finger}`).join(', '),
    ': contact points and normals in the object frame (drag to turn, wheel to zoom).'));
}

async function drawForces(box, skill) {
  const f = await api(`/api/v1/skills/${skill.id}/forces?points=400`);
  const { linePlot } = await import('./plot.js');
  const marks = (skill.params?.phases ?? []).map(ph => [ph.start_ns / 1e9, ph.name]);
  replace(box);
  const normal = h('div', { class: 'plot', id: 'plot-normal' });
  const tangential = h('div', { class: 'plot', id: 'plot-tangential' });
  box.append(normal, tangential);
  const used = f.fingers.filter(fg => fg.normal_n.some(v => v !== 0) || fg.tangential_n.some(v => v !== 0));
  const shown = used.length ? used : f.fingers;
  linePlot(normal, 'Normal force', f.time_s, shown.map(fg => ({ label: fg.finger, values: fg.normal_n })), 'N', marks);
  linePlot(tangential, 'Tangential force', f.time_s, shown.map(fg => ({ label: fg.finger, values: fg.tangential_n })), 'N', marks);
}

async function drawSimilar(box, id) {
  const near = await api(`/api/v1/skills/${id}/similar?k=8`);
  if (!near.items.length) { replace(box, h('p', {}, 'No other skill.')); return; }
  replace(box, h('table', { id: 'similar-table' },
    h('thead', {}, h('tr', {}, h('th', { class: 'num' }, 'id'), h('th', { class: 'num' }, 'distance'), h('th', {}, 'object'),
      h('th', {}, 'grasp type'), h('th', { class: 'num' }, 'contacts'), h('th', { class: 'num' }, 'quality ε'), h('th', { class: 'num' }, 'duration (s)'))),
    h('tbody', {}, near.items.map(n => h('tr', {},
      h('td', { class: 'num' }, h('a', { href: `#/skills/${n.skill_id}` }, String(n.skill_id))),
      h('td', { class: 'num' }, fmt(n.distance, 3)),
      h('td', {}, n.skill.object_name ? `${n.skill.object_shape} “${n.skill.object_name}”` : n.skill.object_shape),
      h('td', {}, n.skill.grasp_type),
      h('td', { class: 'num' }, String(n.skill.contact_count)),
      h('td', { class: 'num' }, fmt(n.skill.quality, 4)),
      h('td', { class: 'num' }, fmt(n.skill.duration_s, 3)))))));
}

// ---------------------------------------------------------------- replays

async function replaysPanel(box, skill) {
  const [hands, replays] = await Promise.all([api('/api/v1/hands'), api(`/api/v1/skills/${skill.id}/replays`)]);
  const select = h('select', { id: 'replay-hand' }, hands.items.map(hd =>
    h('option', { value: hd.name }, `${hd.name}${hd.builtin ? '' : ' (uploaded)'}`)));
  const run = h('button', { type: 'button', id: 'run-replay' }, 'Run replay');
  const status = h('span', { id: 'replay-status' });
  const list = h('ul', { id: 'replay-list' });
  const player = h('div', { id: 'replay-player' });
  const renderList = items => replace(list, items.map(r => h('li', {},
    h('a', { href: '#', onclick: e => { e.preventDefault(); showReplay(player, skill, r); } },
      `#${r.replay_id} on ${r.hand}: `),
    h('span', { class: r.success ? 'ok' : 'bad' }, r.success ? 'held' : `failed (${r.failure_reason ?? 'unknown'})`),
    ` · ${r.created_at} · `, h('a', { href: r.mcap_url, download: '' }, 'MCAP'))));
  renderList(replays.items);
  run.addEventListener('click', async () => {
    run.disabled = true;
    status.textContent = `Replaying on ${select.value}… (simulated at 1 kHz, this takes a few seconds)`;
    try {
      const r = await postJob(`/api/v1/skills/${skill.id}/replays`, { hand: select.value }, job => {
        status.textContent = `Replaying on ${select.value}… (job ${job.job_id}: ${job.state})`;
      });
      status.textContent = `Replay #${r.replay_id} on ${r.hand}: ${r.success ? 'the object was held' : `failed (${r.failure_reason})`}.`;
      const again = await api(`/api/v1/skills/${skill.id}/replays`);
      renderList(again.items);
      await showReplay(player, skill, r);
    } catch (e) {
      status.textContent = '';
      showError(e);
    } finally {
      run.disabled = false;
    }
  });
  replace(box, h('div', { class: 'controls' }, h('label', {}, 'hand ', select), run, status),
    h('p', {}, 'Earlier replays:'), list, player);
}

async function showReplay(box, skill, replay) {
  replace(box, h('p', {}, `Loading replay #${replay.replay_id}…`));
  const frames = await api(`/api/v1/replays/${replay.replay_id}/frames?fps=30`);
  const { View, objectMesh, primitiveMesh, setPose, ForceArrow, THREE } = await import('./scene.js');
  const sceneBox = h('div', { class: 'card' });
  const report = h('pre', { class: 'report', id: 'replay-report' }, JSON.stringify(replay.report, null, 2));
  const play = h('button', { type: 'button', id: 'replay-play' }, 'Pause');
  const scrub = h('input', { type: 'range', id: 'replay-scrub', min: 0, max: Math.max(0, frames.time_s.length - 1), value: 0 });
  const clock = h('span', { id: 'replay-time' }, '0.000 s');
  replace(box, h('h3', {}, `Replay #${replay.replay_id} on ${replay.hand}: `,
    h('span', { class: replay.success ? 'ok' : 'bad' }, replay.success ? 'held' : `failed (${replay.failure_reason})`)),
  h('div', { class: 'cards' }, h('div', {}, sceneBox, h('div', { class: 'controls' }, play, scrub, clock)),
    h('div', {}, h('h3', {}, 'Report'), report)));
  const object = skill.params?.object ?? {};
  const view = new View(sceneBox, 0.15);
  cleanup.push(() => view.dispose());
  view.target.set(...(frames.object_pose[0] ?? [0, 0, 0]).slice(0, 3));
  view.orbit.r = 0.7;
  view.placeCamera();
  const obj = objectMesh(object.shape, object.size ?? [0.04]);
  view.scene.add(obj);
  const links = frames.links.map(link => {
    const g = new THREE.Group();
    for (const s of link.shapes) g.add(primitiveMesh(s, s.fingertip ? 0x2ca02c : 0x8c8c8c));
    view.scene.add(g);
    return g;
  });
  const arrows = [];
  const grid = new THREE.GridHelper(1, 20, 0xaaaaaa, 0xdddddd);
  grid.rotateX(Math.PI / 2);
  view.scene.add(grid);
  const n = frames.time_s.length;
  const show = i => {
    setPose(obj, frames.object_pose[i]);
    frames.link_poses[i].forEach((pose, k) => setPose(links[k], pose));
    const cs = frames.contacts[i];
    while (arrows.length < cs.length) { const a = new ForceArrow(); arrows.push(a); view.scene.add(a.arrow); }
    arrows.forEach((a, k) => { if (k < cs.length) a.set(cs[k].point, cs[k].force); else a.arrow.visible = false; });
    scrub.value = i;
    clock.textContent = `${frames.time_s[i].toFixed(3)} s`;
    view.render();
  };
  let playing = true;
  let frame = 0;
  let last = null;
  let raf = 0;
  icms.frames = 0;
  const t0 = performance.now();
  // The recording's clock runs with the page's: each animation frame shows the recording's
  // frame of that time (drawn only when it changes), looping at the end.
  let clockS = 0;
  let shown = -1;
  const tick = now => {
    icms.frames += 1;
    icms.fps = (1000 * icms.frames) / Math.max(1, now - t0);
    if (playing && n) {
      if (last !== null) clockS += (now - last) / 1000;
      if (clockS > frames.time_s[n - 1]) { clockS = frames.time_s[0]; frame = 0; }
      if (frames.time_s[frame] > clockS) frame = 0;
      while (frame < n - 1 && frames.time_s[frame + 1] <= clockS) frame += 1;
      if (frame !== shown) { show(frame); shown = frame; }
      icms.replayFrame = frame;
    }
    last = now;
    raf = requestAnimationFrame(tick);
  };
  raf = requestAnimationFrame(tick);
  cleanup.push(() => cancelAnimationFrame(raf));
  play.addEventListener('click', () => { playing = !playing; play.textContent = playing ? 'Pause' : 'Play'; });
  scrub.addEventListener('input', () => { frame = Number(scrub.value); clockS = frames.time_s[frame]; show(frame); shown = frame; });
  if (n) { show(0); shown = 0; }
  box.dataset.loaded = String(replay.replay_id);
}

// ---------------------------------------------------------------- sessions

const SESSION_FILTERS = ['scenario', 'hand', 'shape', 'sort', 'limit'];

function sessionFilterForm(params) {
  const text = (name, label, placeholder) => h('label', {}, label,
    h('input', { name, value: params.get(name) ?? '', placeholder }));
  const select = (name, label, options, dflt) => h('label', {}, label, h('select', { name },
    options.map(([v, t]) => h('option', { value: v, selected: (params.get(name) ?? dflt) === v }, t))));
  const form = h('form', { class: 'filters', id: 'session-filters' },
    text('scenario', 'scenario', 'sphere-lift'), text('hand', 'hand', 'glove10'),
    select('shape', 'object', [['', 'any'], ...SHAPES.map(v => [v, v])], ''),
    select('sort', 'order', [['-id', 'newest first'], ['id', 'oldest first']], '-id'),
    select('limit', 'per page', ['25', '50', '100', '200'].map(v => [v, v]), '50'),
    h('button', { type: 'submit', id: 'sessions-apply' }, 'Apply'),
    h('button', { type: 'reset', id: 'sessions-reset' }, 'Clear'));
  form.addEventListener('submit', e => {
    e.preventDefault();
    const q = {};
    for (const name of SESSION_FILTERS) {
      const v = form.elements[name].value.trim();
      if (v !== '' && !(name === 'sort' && v === '-id') && !(name === 'limit' && v === '50')) q[name] = v;
    }
    location.hash = `#/sessions${query(q)}`;
  });
  form.addEventListener('reset', e => { e.preventDefault(); location.hash = '#/sessions'; });
  return form;
}

async function sessionsView(params) {
  // Newest first unless the address asks otherwise; every filter of GET /api/v1/sessions.
  const filters = { sort: '-id' };
  for (const name of SESSION_FILTERS) if (params.get(name)) filters[name] = params.get(name);
  const cursors = (params.get('after') ?? '').split(',').filter(Boolean);
  const tbody = h('tbody', { id: 'session-rows' });
  const status = h('span', { id: 'sessions-status' }, 'Loading…');
  const prev = h('button', { type: 'button', id: 'sessions-prev', disabled: cursors.length === 0 }, '← Previous');
  const next = h('button', { type: 'button', id: 'sessions-next', disabled: true }, 'Next →');
  replace(main, h('h1', {}, 'Sessions'), sessionFilterForm(params),
    h('p', {}, 'Foxglove opens a file by URL only when this server allows its origin (icms serve --cors-origin https://app.foxglove.dev) and the browser can reach the server.'),
    h('table', { id: 'sessions' }, h('thead', {}, h('tr', {},
      ['id', 'stored', 'scenario', 'hand', 'object', 'duration (s)', 'skills', 'first skills', 'file'].map(t => h('th', {}, t)))),
    tbody),
    h('div', { class: 'pager' }, prev, next, status));
  const page = await api(`/api/v1/sessions${query({ ...filters, cursor: cursors.at(-1) })}`);
  const focus = params.get('focus');
  replace(tbody, page.items.map(s => {
    const m = s.meta ?? {};
    return h('tr', { dataset: { id: s.id }, class: String(s.id) === focus ? 'focus' : null },
      h('td', { class: 'num' }, h('a', { href: `#/sessions/${s.id}` }, String(s.id))),
      h('td', { class: 'stored' }, s.created_at.replace('T', ' ').replace(/\.\d+Z$/, 'Z')),
      h('td', { class: 'scenario' }, m.scenario ?? '—'),
      h('td', { class: 'hand' }, m.hand ?? '—'),
      h('td', { class: 'object' }, m.object_shape ?? '—'),
      h('td', { class: 'num' }, fmt((m.duration_ns ?? 0) / 1e9, 3)),
      h('td', { class: 'num' }, String((s.skill_ids ?? []).length)),
      h('td', { class: 'skills' }, skillLinks(s)),
      h('td', {}, h('a', { href: s.mcap_url, download: '' }, 'MCAP'), ' · ', foxgloveLink(s.mcap_url)));
  }));
  const filtered = SESSION_FILTERS.some(n => n !== 'sort' && n !== 'limit' && filters[n]);
  status.textContent = page.items.length
    ? `page ${cursors.length + 1}: ${page.items.length} sessions${page.next_cursor ? '' : ' (last page)'}`
    : (filtered ? 'No session matches these filters.' : 'No session stored.');
  const go = list => {
    const q = { ...filters };
    if (q.sort === '-id') delete q.sort;
    if (list.length) q.after = list.join(',');
    location.hash = `#/sessions${query(q)}`;
  };
  if (page.next_cursor) {
    next.disabled = false;
    next.addEventListener('click', () => go([...cursors, page.next_cursor]));
  }
  prev.addEventListener('click', () => go(cursors.slice(0, -1)));
  setReady('sessions');
}

/** Links to a session's first skills; the rest (a session may hold thousands) on its page. */
function skillLinks(s, shown = 5) {
  const ids = s.skill_ids ?? [];
  const links = ids.slice(0, shown).map((k, i) => [i ? ' ' : '', h('a', { href: `#/skills/${k}` }, `#${k}`)]);
  if (ids.length > shown) links.push(' ', h('a', { href: `#/sessions/${s.id}`, class: 'more' }, `… ${ids.length - shown} more`));
  return links;
}

/** The link that opens a session's MCAP file in app.foxglove.dev (by URL: see the README). */
function foxgloveLink(mcapUrl) {
  const url = `${location.origin}${mcapUrl}`;
  return h('a', { href: `https://app.foxglove.dev/~/view?ds=remote-file&ds.url=${encodeURIComponent(url)}`, target: '_blank', rel: 'noopener' }, 'open in Foxglove');
}

async function sessionView(idText) {
  const id = Number(idText);
  if (!Number.isInteger(id)) throw new ApiError(400, 'Bad Request', `session id ${JSON.stringify(idText)} is not an integer`);
  const s = await api(`/api/v1/sessions/${id}`);
  const m = s.meta ?? {};
  const extra = m.extra && typeof m.extra === 'object' ? Object.entries(m.extra) : [];
  replace(main,
    h('p', {}, h('a', { href: '#/sessions' }, '← all sessions')),
    h('h1', {}, `Session ${s.id}`),
    h('div', { class: 'cards' },
      h('section', { class: 'card' }, facts([
        ['scenario', h('span', { id: 'session-scenario' }, m.scenario ?? '—')],
        ['seed', m.seed === undefined || m.seed === null ? '—' : String(m.seed)],
        ['hand', m.hand ?? '—'],
        ['object', `${m.object_shape ?? '—'}, ${fmt(m.object_mass, 3)} kg, μ ${fmt(m.mu, 2)}`],
        ['duration', `${fmt((m.duration_ns ?? 0) / 1e9, 3)} s`],
        ['started', m.started_at ?? '—'],
        ['stored', s.created_at],
        ['segmentation version', String(s.segmentation_version)],
        ['file', [h('a', { href: s.mcap_url, download: '' }, 'download MCAP'), ` (${s.size_bytes} bytes) · `, foxgloveLink(s.mcap_url)]],
        ['SHA-256', s.sha256],
        ['skills', (s.skill_ids ?? []).map((k, i) => [i ? ' ' : '', h('a', { href: `#/skills/${k}` }, `#${k}`)])],
      ])),
      h('section', { class: 'card' }, h('h2', {}, 'Recorded metadata'),
        h('table', {}, h('tbody', {}, extra.map(([k, v]) => h('tr', {}, h('th', {}, k),
          h('td', {}, h('code', { class: 'meta' }, typeof v === 'string' ? v : JSON.stringify(v))))))))));
  setReady('session');
}

// ---------------------------------------------------------------- hands

async function handsView() {
  const hands = await api('/api/v1/hands');
  const cards = h('div', { class: 'cards', id: 'hands' });
  const errorBox = h('div', { id: 'upload-result', role: 'status' });
  const form = h('form', { id: 'hand-upload' },
    h('label', {}, 'Hand spec (JSON)', h('textarea', { name: 'spec', rows: 8, placeholder: '{"name": "my-hand", "fingertips": [...], "torque_limit": 0.7}' })),
    h('label', {}, 'URDF', h('textarea', { name: 'urdf', rows: 8, placeholder: '<robot name="my-hand">…</robot>' })),
    h('button', { type: 'submit', id: 'upload-hand' }, 'Upload hand'), errorBox);
  form.addEventListener('submit', async e => {
    e.preventDefault();
    replace(errorBox);
    let spec;
    try {
      spec = JSON.parse(form.elements.spec.value);
    } catch (err) {
      const pe = new ApiError(0, 'The spec is not JSON', String(err.message));
      replace(errorBox, h('p', { class: 'bad' }, h('strong', {}, pe.title), ': ', pe.detail));
      showError(pe);
      return;
    }
    try {
      const hand = await post('/api/v1/hands', { spec, urdf: form.elements.urdf.value });
      replace(errorBox, h('p', { class: 'ok' }, `Stored hand ${hand.name}.`));
      await route();
    } catch (err) {
      if (err instanceof ApiError) {
        replace(errorBox, h('p', { class: 'bad', id: 'upload-error' }, h('strong', {}, err.title), ': ', err.detail));
      }
      showError(err);
    }
  });
  replace(main, h('h1', {}, 'Robot hands'), cards, h('h2', {}, 'Upload a hand'), form);
  for (const hd of hands.items) {
    const box = h('div', { class: 'hand3d' });
    cards.appendChild(h('section', { class: 'card', dataset: { hand: hd.name } },
      h('h2', {}, hd.name, hd.builtin ? ' (built in)' : ' (uploaded)'),
      facts([['fingers', hd.fingers.join(', ')], ['DOF', String(hd.dof)],
        ['torque limit', `${fmt(hd.torque_limit[0], 2)}–${fmt(hd.torque_limit[1], 2)} N·m`]]), box));
    drawHand(box, hd.name).catch(err => replace(box, h('p', { class: 'bad' }, `3D view unavailable: ${err.title ?? ''} ${err.detail ?? err.message ?? err}`)));
  }
  setReady('hands');
}

async function drawHand(box, name) {
  const geometry = await api(`/api/v1/hands/${encodeURIComponent(name)}/geometry`);
  const { View, primitiveMesh, setPose, THREE } = await import('./scene.js');
  const view = new View(box, 0.08);
  cleanup.push(() => view.dispose());
  const hand = new THREE.Group();
  for (const link of geometry.links) {
    const g = new THREE.Group();
    setPose(g, link.pose);
    for (const s of link.shapes) g.add(primitiveMesh(s, s.fingertip ? 0x2ca02c : 0x8c8c8c));
    hand.add(g);
  }
  view.scene.add(hand);
  // Every link in view, whatever the hand's size (a gripper's long fingers too).
  view.frame(hand);
  view.render();
}

document.getElementById('error-close').addEventListener('click', clearError);
window.addEventListener('hashchange', route);
route();
