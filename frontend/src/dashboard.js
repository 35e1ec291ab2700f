// The dashboard (/): drop files, choose the job kind and its parameters, submit; the jobs list, live by SSE.

import { ApiError, ENDED, call, el, events, fmtSeconds, jobSeconds, json, keyBar, plain } from './api.js';
import { paramsForm } from './form.js';

const $ = (s) => document.querySelector(s);
const state = { kinds: [], forms: {}, jobs: new Map(), gone: new Set(), filter: { status: '', kind: '' } };
const keys = keyBar($('#keybar'), () => start());

function setMessage(text, kind = 'info') {
  const m = $('#submit-message');
  m.textContent = text; m.className = `message ${kind}`;
}

// ---- the form -------------------------------------------------------------------------------------------
function showKind(name) {
  for (const [k, f] of Object.entries(state.forms)) f.node.hidden = k !== name;
  const kind = state.kinds.find((k) => k.name === name);
  $('#stl-field').hidden = !kind.takes_stl;
  $('#kind-help').textContent = `${kind.help}. Input: ${kind.input_help}.`;
}

function listFiles() {
  const files = [...$('#file').files];
  $('#file-names').textContent = files.length > 1 ? files.map((f) => f.name).join(', ') : '';
}

async function submit(ev) {
  ev.preventDefault();
  const files = [...$('#file').files];
  const kind = $('#kind').value;
  const [params, errors] = state.forms[kind].read();
  if (!files.length) { setMessage('Choose or drop at least one file.', 'error'); return; }
  if (errors.length) { setMessage(`Check the parameters: ${errors.join('; ')}.`, 'error'); return; }
  const stl = $('#stl').files[0];
  $('#submit').disabled = true;
  let made = 0;
  try {
    for (const f of files) {
      setMessage(`Uploading ${f.name}…`);
      const body = new FormData();
      body.append('file', f, f.name);
      body.append('kind', kind);
      body.append('params', JSON.stringify(params));
      if (stl && !$('#stl-field').hidden) body.append('stl', stl, stl.name);
      const job = await json('/v1/jobs', { method: 'POST', body });
      upsert(job);
      made += 1;
    }
    setMessage(`Submitted ${made} job${made === 1 ? '' : 's'}.`, 'ok');
  } catch (e) {
    if (e instanceof ApiError && e.status === 401) keys.ask();
    setMessage(`${made ? `Submitted ${made}; then ` : ''}${plain({ code: e.code, message: e.message })} (${e.code})`, 'error');
  } finally { $('#submit').disabled = false; }
}

function dropZone() {
  const zone = $('#drop');
  for (const t of ['dragenter', 'dragover']) zone.addEventListener(t, (e) => { e.preventDefault(); zone.classList.add('over'); });
  for (const t of ['dragleave', 'drop']) zone.addEventListener(t, () => zone.classList.remove('over'));
  zone.addEventListener('drop', (e) => {
    e.preventDefault();
    $('#file').files = e.dataTransfer.files;
    listFiles();
  });
  $('#file').addEventListener('change', listFiles);
}

// ---- the jobs list --------------------------------------------------------------------------------------
const STATUS_WORDS = { queued: 'queued', running: 'running', succeeded: 'succeeded', failed: 'failed', cancelled: 'cancelled' };

function matches(job) {
  const f = state.filter;
  return (!f.status || job.status === f.status) && (!f.kind || job.kind === f.kind);
}

function row(job) {
  const ended = ENDED.includes(job.status);
  const name = job.input?.file?.name || job.id;
  const pct = Math.round((job.status === 'succeeded' ? 1 : job.progress || 0) * 100);
  const err = job.error ? `${plain(job.error)} (${job.error.code})` : '';
  const action = ended
    ? el('button', { type: 'button', class: 'secondary', text: 'Delete', 'aria-label': `Delete ${name}`, onclick: () => remove(job) })
    : el('button', { type: 'button', class: 'secondary', text: 'Cancel', 'aria-label': `Cancel ${name}`, onclick: () => remove(job) });
  return el('tr', { 'data-job': job.id, 'data-status': job.status },
    el('td', { class: 'name' }, el('a', { href: `/jobs/${job.id}`, text: name, title: name })),
    el('td', { text: job.kind }),
    el('td', {}, el('span', { class: `badge ${job.status}`, text: STATUS_WORDS[job.status] || job.status })),
    el('td', { class: 'progress-cell' },
      el('div', { class: 'bar', role: 'progressbar', 'aria-valuemin': 0, 'aria-valuemax': 100, 'aria-valuenow': pct,
        'aria-label': `progress of ${name}` }, el('div', { class: 'fill', style: `width:${pct}%` })),
      el('span', { class: 'stage', text: err || job.stage || '', title: err || job.stage || '' })),
    el('td', { class: 'num duration', text: fmtSeconds(jobSeconds(job)) }),
    el('td', { class: 'actions' }, action));
}

function render() {
  const body = $('#jobs tbody');
  const shown = [...state.jobs.values()].filter(matches).sort((a, b) => (a.created_at < b.created_at ? 1 : -1));
  const rows = shown.map(row);
  body.replaceChildren(...rows);
  $('#jobs-empty').hidden = shown.length > 0;
}

// A list and an event travel on other connections than a DELETE or a cancel, so one that left the server before
// the change can arrive after it: a deleted job never comes back and an ended one never runs again.
function stale(job) {
  const old = state.jobs.get(job.id);
  return state.gone.has(job.id) || (old !== undefined && ENDED.includes(old.status) && !ENDED.includes(job.status));
}

function forget(id) {
  state.gone.add(id);
  state.jobs.delete(id);
  render();
}

function upsert(job) {
  if (stale(job)) return;
  state.jobs.set(job.id, job);
  const old = document.querySelector(`#jobs tr[data-job="${job.id}"]`);
  if (old && matches(job)) old.replaceWith(row(job));
  else render();
}

async function remove(job) {
  try {
    const res = await call(`/v1/jobs/${job.id}`, { method: 'DELETE' });
    if (res.status === 204) forget(job.id); else upsert(await res.json());
  } catch (e) { setMessage(`${plain({ code: e.code, message: e.message })} (${e.code})`, 'error'); }
}

async function load() {
  const q = new URLSearchParams({ limit: '100' });
  if (state.filter.status) q.set('status', state.filter.status);
  if (state.filter.kind) q.set('kind', state.filter.kind);
  const page = await json(`/v1/jobs?${q}`);
  for (const j of page.jobs) if (!stale(j)) state.jobs.set(j.id, j);
  render();
}

let live = null;
async function follow() {
  live?.abort();
  live = new AbortController();
  const signal = live.signal;
  let wait = 1000;
  while (!signal.aborted) {
    try {
      $('#live').textContent = 'live';
      for await (const m of events('/v1/events', signal)) {
        wait = 1000;
        const d = JSON.parse(m.data);
        if (m.event === 'deleted') forget(d.id); else if (m.event === 'job') upsert(d);
      }
    } catch (e) {
      if (signal.aborted) return;
      if (e instanceof ApiError && e.status === 401) { keys.ask(); return; }
    }
    $('#live').textContent = 'reconnecting…';
    await new Promise((r) => setTimeout(r, wait));
    wait = Math.min(wait * 2, 15000);
    await load().catch(() => {});
  }
}

function tick() {  // running jobs' durations, without re-rendering rows
  for (const tr of document.querySelectorAll('#jobs tr[data-status="running"]')) {
    const job = state.jobs.get(tr.dataset.job);
    if (job) tr.querySelector('.duration').textContent = fmtSeconds(jobSeconds(job));
  }
}

async function start() {
  try {
    await load();
    follow();
  } catch (e) {
    if (e instanceof ApiError && e.status === 401) keys.ask();
    else setMessage(`The jobs could not be listed: ${plain({ code: e.code, message: e.message })}`, 'error');
  }
}

async function init() {
  state.kinds = await json('/v1/kinds');
  const select = $('#kind');
  for (const k of state.kinds) {
    select.append(el('option', { value: k.name, text: k.name }));
    state.forms[k.name] = paramsForm(k);
    $('#params').append(state.forms[k.name].node);
  }
  select.addEventListener('change', () => showKind(select.value));
  showKind(select.value);
  dropZone();
  $('#submit-form').addEventListener('submit', submit);
  for (const f of ['status', 'kind']) {
    $(`#filter-${f}`).addEventListener('change', (e) => { state.filter[f] = e.target.value; render(); load(); });
  }
  setInterval(tick, 1000);
  await start();
}

init();
