// The API from the browser: the user's key (session storage), JSON calls, problem+json errors, downloads and
// server-sent events read from fetch (so the key travels in a header, never in a URL).

const KEY = 'amprep.apiKey';

export function apiKey() { return sessionStorage.getItem(KEY) || ''; }
export function setApiKey(k) { if (k) sessionStorage.setItem(KEY, k); else sessionStorage.removeItem(KEY); }

/** The statuses a job never leaves. */
export const ENDED = ['succeeded', 'failed', 'cancelled'];

export class ApiError extends Error {
  constructor(status, code, detail) { super(detail || code); this.status = status; this.code = code; }
}

/** Plain words for the stable error codes (the code is always shown beside them). */
export const PLAIN = {
  unsupported_format: 'The file is not STEP, IGES, BREP, ACIS (SAT, SAB, DXF) or STL.',
  unreadable_cad: 'The CAD file could not be read.',
  unreadable_mesh: 'The STL file could not be read.',
  empty_model: 'The file holds no solid or surface to mesh.',
  invalid_parameter: 'A parameter is out of its bounds.',
  invalid_request: 'The request was not valid.',
  meshing_failed: 'The part could not be meshed.',
  write_failed: 'The result could not be written.',
  stl_mismatch: 'Your STL does not fit this CAD part.',
  output_too_large: 'The result would have more triangles than allowed.',
  upload_too_large: 'The file is larger than the server accepts.',
  worker_crashed: 'The worker died on this input (it may crash the CAD kernel).',
  time_limit: 'The job ran over its time limit.',
  memory_limit: 'The job ran out of its memory allowance.',
  cancelled: 'The job was cancelled.',
  unauthorized: 'This server needs a valid API key.',
  not_found: 'No such job (or not yours).',
  unavailable: 'The server cannot reach its queue right now: try again shortly.',
  internal_error: 'An error of ours: please report it.',
};

export function plain(err) {
  if (!err) return '';
  const words = PLAIN[err.code] || '';
  return words && err.message && !err.message.startsWith(words) ? `${words} ${err.message}` : (err.message || words);
}

function headers(extra = {}) {
  const k = apiKey();
  return k ? { ...extra, Authorization: `Bearer ${k}` } : extra;
}

async function problemOf(res) {
  try {
    const p = await res.json();
    return new ApiError(res.status, p.code || 'error', p.detail || p.title || res.statusText);
  } catch { return new ApiError(res.status, 'error', res.statusText); }
}

/** fetch() with the key; throws ApiError on a non-2xx answer. */
export async function call(path, opts = {}) {
  const res = await fetch(path, { ...opts, headers: headers(opts.headers || {}) });
  if (!res.ok) throw await problemOf(res);
  return res;
}

export async function json(path, opts = {}) { return (await call(path, opts)).json(); }

/** The body as an ArrayBuffer, reporting progress(fraction) from Content-Length as it arrives. */
export async function bytes(path, progress = () => {}) {
  const res = await call(path);
  const total = Number(res.headers.get('Content-Length')) || 0;
  if (!res.body || !total) return res.arrayBuffer();
  const out = new Uint8Array(total);
  const reader = res.body.getReader();
  let at = 0;
  for (;;) {
    const { done, value } = await reader.read();
    if (done) break;
    out.set(value, at);
    at += value.length;
    progress(at / total);
  }
  return out.buffer.slice(0, at);
}

/** Save a response as a file named `name` (fetched with the key, so it works on a keyed server). */
export async function download(path, name) {
  const blob = await (await call(path)).blob();
  const url = URL.createObjectURL(blob);
  const a = document.createElement('a');
  a.href = url; a.download = name; document.body.append(a); a.click(); a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 60000);
}

/** Server-sent events of `path` as {event, data} objects, until `signal` aborts or the stream ends. */
export async function* events(path, signal) {
  const res = await call(path, { headers: { Accept: 'text/event-stream' }, signal });
  const reader = res.body.pipeThrough(new TextDecoderStream()).getReader();
  let buf = '';
  for (;;) {
    const { done, value } = await reader.read();
    if (done) return;
    buf += value.replace(/\r\n?/g, '\n');
    let cut;
    while ((cut = buf.indexOf('\n\n')) >= 0) {
      const block = buf.slice(0, cut);
      buf = buf.slice(cut + 2);
      let event = 'message'; const data = [];
      for (const line of block.split('\n')) {
        if (line.startsWith('event:')) event = line.slice(6).trim();
        else if (line.startsWith('data:')) data.push(line.slice(5).replace(/^ /, ''));
      }
      if (data.length) yield { event, data: data.join('\n') };
    }
  }
}

export function fmtBytes(n) {
  if (n < 1024) return `${n} B`;
  const u = ['KB', 'MB', 'GB']; let i = -1;
  do { n /= 1024; i += 1; } while (n >= 1024 && i < u.length - 1);
  return `${n.toFixed(n < 10 ? 1 : 0)} ${u[i]}`;
}

export function fmtSeconds(s) {
  if (s == null || !isFinite(s)) return '';
  if (s < 60) return `${s.toFixed(s < 10 ? 1 : 0)} s`;
  const m = Math.floor(s / 60);
  return m < 60 ? `${m} min ${Math.round(s % 60)} s` : `${Math.floor(m / 60)} h ${m % 60} min`;
}

/** Seconds a job has run (or ran): finished − started, or now − started while it runs. */
export function jobSeconds(job) {
  if (!job.started_at) return null;
  const end = job.finished_at ? Date.parse(job.finished_at) : Date.now();
  return Math.max(0, (end - Date.parse(job.started_at)) / 1000);
}

export function fmtNumber(x, digits = 4) {
  if (x == null) return '–';
  if (typeof x !== 'number') return String(x);
  if (Number.isInteger(x)) return x.toLocaleString('en');
  return Math.abs(x) >= 1000 ? x.toLocaleString('en', { maximumFractionDigits: 1 }) : Number(x.toPrecision(digits)).toString();
}

export function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v == null || v === false) continue;
    if (k === 'class') e.className = v;
    else if (k === 'text') e.textContent = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? '' : v);
  }
  for (const c of children.flat()) if (c != null) e.append(c);
  return e;
}

/** The key bar: shows a key field when the server asks for one (a 401), stores the key for this tab. */
export function keyBar(root, onKey) {
  const input = el('input', { type: 'password', id: 'api-key', autocomplete: 'off', placeholder: 'API key' });
  const form = el('form', { class: 'keybar', hidden: true, 'aria-label': 'API key' },
    el('label', { for: 'api-key', text: 'This server needs an API key:' }), input,
    el('button', { type: 'submit', text: 'Use key' }));
  form.addEventListener('submit', (ev) => { ev.preventDefault(); setApiKey(input.value.trim()); form.hidden = true; onKey(); });
  root.append(form);
  return { ask() { form.hidden = false; input.focus(); } };
}
