// The job page (/jobs/{id}): status (live), the 3D view with error colouring, defects and picking, before/after for
// refine jobs, downloads, the report's tables and plots.

import { ApiError, ENDED, bytes, call, download, el, events, fmtBytes, fmtNumber, fmtSeconds, jobSeconds, json, keyBar, plain } from './api.js';
import { cssRamp, range } from './colours.js';
import { defectItems, merged } from './defects.js';
import { parseSTL } from './stl.js';
import { Box3, DEFECT, HIGHLIGHT, Vector3, Viewer } from './viewer.js';

const $ = (s) => document.querySelector(s);
const jobId = decodeURIComponent(location.pathname.split('/').filter(Boolean).pop());
const page = { job: null, report: null, viewers: [], fields: {}, faceIds: null, items: [] };
const keys = keyBar($('#keybar'), () => start());
window.amprep = page;  // for tests and bench/dashboard.py: page.viewers, page.firstFrame

const FIELD_NAMES = { chordal_error: 'chordal error', cusp_height: 'cusp height' };
const MESHES = ['mesh.stl', 'part.stl', 'refined.stl'];

function art(name) { return page.job.artifacts.find((a) => a.name === name); }

function header(job) {
  const name = job.input?.file?.name || job.id;
  document.title = `amprep — ${name}`;
  $('#title').textContent = name;
  const pct = Math.round((job.status === 'succeeded' ? 1 : job.progress || 0) * 100);
  $('#status').replaceChildren(
    el('span', { class: `badge ${job.status}`, text: job.status }),
    el('span', { class: 'meta', text: ` ${job.kind} · ${job.stage || ''} · ${fmtSeconds(jobSeconds(job))}` }),
    el('div', { class: 'bar', role: 'progressbar', 'aria-valuenow': pct, 'aria-valuemin': 0, 'aria-valuemax': 100,
      'aria-label': 'progress', style: 'max-width:320px;margin-top:6px' }, el('div', { class: 'fill', style: `width:${pct}%` })));
  $('#error').hidden = !job.error;
  if (job.error) $('#error').textContent = `${plain(job.error)} (${job.error.code})`;
}

function artifacts(job) {
  const list = $('#artifacts');
  list.replaceChildren(...job.artifacts.map((a) => el('li', {},
    el('button', { type: 'button', class: 'secondary', text: a.name, 'data-artifact': a.name,
      onclick: () => download(a.url, a.name) }), el('span', { class: 'size', text: fmtBytes(a.size) }))));
  $('#zip').hidden = !job.artifacts.length;
}

// ---- the 3D view -----------------------------------------------------------------------------------------
async function loadMesh(name, container, caption) {
  const progress = el('div', { class: 'bar loading', role: 'progressbar', 'aria-label': `loading ${name}` }, el('div', { class: 'fill', style: 'width:0%' }));
  container.append(progress);
  const buf = await bytes(art(name).url, (f) => { progress.firstChild.style.width = `${Math.round(100 * f)}%`; });
  const parsed = parseSTL(buf);
  progress.remove();
  const v = new Viewer(container, caption);
  v.setMesh(parsed);
  return v;
}

async function field(name, type = Float32Array) {
  if (!art(name)) return null;
  return new type(await (await call(art(name).url)).arrayBuffer());
}

function legend(name, lo, hi, unit) {
  const lg = $('#legend');
  lg.hidden = !name;
  if (!name) return;
  lg.replaceChildren(el('span', { text: `${fmtNumber(lo, 3)}` }), el('span', { class: 'ramp', style: `background:${cssRamp()}` }),
    el('span', { text: `${fmtNumber(hi, 3)} ${unit}` }), el('span', { class: 'meta', text: `${FIELD_NAMES[name]}; grey: not measured` }));
}

function colour(name) {
  const main = page.viewers[page.viewers.length - 1];
  const values = page.fields[name];
  if (!values) { main.colourBy(null); legend(null); main.container.dataset.colour = 'plain'; return; }
  const [lo, hi] = range(values);
  main.colourBy(values, lo, hi);
  legend(name, lo, hi, 'mm');
  main.container.dataset.colour = name;
}

function showPick(v, t) {
  const box = $('#pick');
  if (t < 0) { box.replaceChildren(el('p', { class: 'meta', text: 'No triangle under the pointer.' })); v.clearOverlay('pick'); return; }
  v.draw_overlay('pick', { triangles: [...v.corners(t)] }, HIGHLIGHT, true);
  const fid = page.faceIds ? page.faceIds[t] : -1;
  const face = fid >= 0 ? page.report?.faces?.[fid] : null;
  const rows = [['triangle', t], ['CAD face', fid >= 0 ? fid : 'none (no CAD)'], ['surface', face?.surface_type || '–']];
  for (const [k, label] of Object.entries(FIELD_NAMES)) {
    if (page.fields[k]) rows.push([label, Number.isFinite(page.fields[k][t]) ? `${fmtNumber(page.fields[k][t])} mm` : 'not measured']);
  }
  if (face?.chordal_error) rows.push(['face chordal mean / max', `${fmtNumber(face.chordal_error.mean)} / ${fmtNumber(face.chordal_error.max)} mm`]);
  box.replaceChildren(el('dl', {}, rows.flatMap(([k, val]) => [el('dt', { text: k }), el('dd', { text: String(val) })])));
  box.dataset.triangle = String(t);
}

function defects(v) {
  page.items = defectItems(page.report || {}, (t) => v.corners(t));
  const list = $('#defects');
  $('#defects-none').hidden = page.items.length > 0;
  v.draw_overlay('defects', merged(page.items), DEFECT);
  list.replaceChildren(...page.items.map((it, i) => el('li', {}, el('button', {
    type: 'button', 'aria-pressed': 'false', 'data-defect': i, text: it.label, onclick: (e) => select(v, i, e.target) }))));
}

function select(v, i, button) {
  for (const b of document.querySelectorAll('#defects button')) b.setAttribute('aria-pressed', String(b === button));
  const it = page.items[i];
  v.draw_overlay('selected', { ...it, points: [...(it.points || []), ...(it.segments || [])] }, HIGHLIGHT, true);
  const pts = [...(it.segments || []), ...(it.triangles || []), ...(it.points || [])];
  if (pts.length) {
    const box = new Box3();
    for (let k = 0; k < pts.length; k += 3) box.expandByPoint(new Vector3(pts[k], pts[k + 1], pts[k + 2]));
    const size = box.getSize(new Vector3()).length();
    const r = Math.max(size, v.mesh.geometry.boundingSphere.radius * 0.3);
    box.expandByScalar(r / 2);
    v.fit(box, 1.4);
  }
  v.container.dataset.selected = String(i);
}

async function viewer(job) {
  const views = $('#views');
  const mainName = MESHES.find((n) => art(n));
  if (!mainName) { $('#viewer-card').hidden = true; return; }
  const t0 = performance.now();
  const two = job.kind === 'refine' && art('before.stl');
  views.classList.toggle('two', Boolean(two));
  if (two) {
    const before = el('div', { class: 'view', id: 'view-before' });
    views.append(before);
    page.viewers.push(await loadMesh('before.stl', before, 'before'));
  }
  const box = el('div', { class: 'view', id: 'view-main' });
  views.append(box);
  const v = await loadMesh(mainName, box, two ? 'after' : mainName);
  page.viewers.push(v);
  if (two) page.viewers[0].link(v);
  v.onDraw = () => {
    if (page.firstFrame) return;
    page.firstFrame = performance.now() - t0;  // ms from asking for the mesh to its first frame
    page.firstFrameAt = performance.now();  // ms since the page started loading
    box.dataset.ready = 'true';
    setTimeout(() => page.viewers.forEach((w) => w.timeFrame()), 0);
  };
  v.request();
  for (const n of Object.keys(FIELD_NAMES)) page.fields[n] = await field(`${n}.f32`);
  page.faceIds = await field('face_id.i32', Int32Array);
  const select_ = $('#colour');
  select_.replaceChildren(el('option', { value: '', text: 'plain' }),
    ...Object.keys(FIELD_NAMES).filter((n) => page.fields[n]).map((n) => el('option', { value: n, text: FIELD_NAMES[n] })));
  select_.disabled = select_.options.length < 2;
  select_.onchange = () => colour(select_.value);
  $('#wireframe').onchange = (e) => page.viewers.forEach((w) => w.setWireframe(e.target.checked));
  v.onWireframe = (on) => { $('#wireframe').checked = on; };
  $('#fit').onclick = () => v.fit();
  let down = null;
  v.renderer.domElement.addEventListener('pointerdown', (e) => { down = [e.clientX, e.clientY]; });
  v.renderer.domElement.addEventListener('pointerup', (e) => {
    if (down && Math.hypot(e.clientX - down[0], e.clientY - down[1]) < 4) showPick(v, v.pick(e.clientX, e.clientY));
  });
  defects(v);
}

// ---- the report ------------------------------------------------------------------------------------------
function table(caption, rows, head) {
  return el('table', {}, el('caption', { class: 'sr-only', text: caption }),
    head ? el('thead', {}, el('tr', {}, head.map((h) => el('th', { scope: 'col', text: h })))) : null,
    el('tbody', {}, rows.map((r) => el('tr', {}, el('th', { scope: 'row', text: r[0] }), r.slice(1).map((c) => el('td', { class: 'num', text: fmtNumber(c) }))))));
}

function report(r) {
  const out = $('#report');
  const parts = [];
  const m = r.mesh || {};
  parts.push(el('h3', { text: 'Mesh' }), table('mesh checks', [
    ['triangles', m.triangles], ['vertices', m.vertices], ['watertight', String(m.watertight)], ['manifold3d accepts', String(m.manifold3d)],
    ['closed once joined by position (as an STL reader joins it)', m.closed_by_position == null ? undefined : String(m.closed_by_position)],
    ['boundary edges', m.boundary_edges], ['non-manifold edges', m.nonmanifold_edges], ['self-intersections', m.self_intersections?.count],
    ['shells', m.shells], ['volume (mm³)', m.volume], ['area (mm²)', m.area]].filter((x) => x[1] !== undefined)));
  const g = r.meshing;
  if (g) {
    parts.push(el('h3', { text: 'Meshing' }), table('meshing', [
      ['tolerance (mm)', g.tolerance], ['max chordal error (mm)', g.max_chordal_error],
      ['within tolerance', g.within_tolerance == null ? undefined : String(g.within_tolerance)],
      ['faces miss their shared edges by, at most (mm)', g.brep_gap || undefined],
      ['edge nodes moved to join their faces, at most (mm)', g.seat_move || undefined],
      ['estimated triangles', g.estimated_triangles],
      ['faces unmeshed', g.unmeshed_faces?.length],
      ...Object.entries(g.faces_by_method || {}).map(([k, n]) => [`faces meshed by ${k}`, n])].filter((x) => x[1] !== undefined)));
  }
  if (r.notes?.length) parts.push(el('h3', { text: 'Notes' }), el('ul', {}, r.notes.map((n) => el('li', { text: n }))));
  const stats = [];
  if (r.chordal_error) stats.push(['chordal error (mm)', r.chordal_error.mean, r.chordal_error.max]);
  for (const k of ['approximate', 'bounding_box']) if (r.cusp_height?.[k]) stats.push([`cusp height, ${k.replace('_', ' ')} (mm)`, r.cusp_height[k].mean, r.cusp_height[k].max]);
  for (const k of ['angle', 'area', 'edge']) if (r.regularity?.[k]) stats.push([`${k} regularity`, r.regularity[k].mean, '']);
  if (stats.length) parts.push(el('h3', { text: 'Errors' }), table('error statistics', stats, ['', 'mean', 'max']));
  if (r.issues?.length) {
    parts.push(el('h3', { text: 'Issues' }), el('ul', {}, r.issues.map((i) => el('li', { text: `${i.severity}: ${i.message} (${i.code}, ${i.count})` }))));
  }
  if (r.refined_faces?.length) {
    parts.push(el('h3', { text: 'Refined faces' }), el('div', { class: 'scroll' }, table('refined faces', r.refined_faces.map((f) => [
      `${f.id} ${f.surface_type || ''}`, f.triangles_before, f.triangles_after, f.chordal_error_before?.mean, f.chordal_error_after?.mean]),
    ['face', 'triangles before', 'after', 'chordal mean before (mm)', 'after (mm)'])));
  }
  if (r.faces?.length) {
    parts.push(el('h3', { text: `Faces (${r.faces.length})` }), el('div', { class: 'scroll' }, table('per-face scores', r.faces.map((f) => [
      `${f.id} ${f.surface_type}`, f.triangles, f.chordal_error?.mean, f.chordal_error?.max, f.cusp_height?.mean, f.cylindricity?.zone ?? '']),
    ['face', 'triangles', 'chordal mean (mm)', 'chordal max (mm)', 'cusp mean (mm)', 'cylindricity (mm)'])));
  }
  out.replaceChildren(...parts);
}

async function plots(job) {
  const pngs = job.artifacts.filter((a) => a.media_type === 'image/png');
  const box = $('#plots');
  box.hidden = !pngs.length;
  for (const a of pngs) {
    const blob = await (await call(a.url)).blob();
    box.querySelector('.plots').append(el('img', { src: URL.createObjectURL(blob), alt: `plot: ${a.name.replace(/[_.]/g, ' ').replace(' png', '')}` }));
  }
}

async function ended(job) {
  artifacts(job);
  if (job.status !== 'succeeded') { $('#viewer-card').hidden = true; return; }
  const summary = art('report.json') || art('summary.json');  // analyze and refine: report.json; convert: summary.json
  if (summary) { page.report = await json(summary.url); report(page.report); }
  await viewer(job);
  await plots(job);
}

async function start() {
  try {
    page.job = await json(`/v1/jobs/${jobId}`);
  } catch (e) {
    if (e instanceof ApiError && e.status === 401) { keys.ask(); return; }
    $('#error').hidden = false; $('#error').textContent = `${plain({ code: e.code, message: e.message })} (${e.code})`;
    return;
  }
  header(page.job);
  if (ENDED.includes(page.job.status)) { await ended(page.job); return; }
  for await (const m of events(`/v1/jobs/${jobId}/events`)) {
    if (m.event !== 'job') continue;
    page.job = JSON.parse(m.data);
    header(page.job);
  }
  await ended(page.job);
}

$('#zip').onclick = () => download(`/v1/jobs/${jobId}/archive`, `amprep-${jobId}.zip`);
start();
