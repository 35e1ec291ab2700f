// The submit form, generated from GET /v1/kinds: one field per parameter with its default, bounds, unit and help.

import { el } from './api.js';

const label = (name) => name.replace(/_/g, ' ');

function inputFor(p, id) {
  const common = { id, name: p.name, 'aria-describedby': `${id}-help` };
  if (p.type === 'bool') return el('input', { ...common, type: 'checkbox', checked: p.default === true });
  if (p.type === 'choice') {
    return el('select', common, p.choices.map((c) => el('option', { value: c, selected: c === p.default, text: c })));
  }
  if (p.type === 'float' || p.type === 'int') {
    return el('input', { ...common, type: 'number', inputmode: 'decimal', step: p.type === 'int' ? '1' : 'any',
      min: p.ge ?? p.gt, max: p.le ?? p.lt, placeholder: p.default == null ? 'none' : String(p.default) });
  }
  const placeholder = p.type === 'vector3' ? (p.default || []).join(',') : p.type === 'ids' ? 'e.g. 3,7'
    : p.default == null ? '' : String(p.default);
  return el('input', { ...common, type: p.type === 'url' ? 'url' : 'text', placeholder });
}

/** Check one field's value against its definition: [value, error]; value undefined = leave the default. */
export function readField(p, input) {
  if (p.type === 'bool') return [input.checked === (p.default === true) ? undefined : input.checked, null];
  if (p.type === 'choice') return [input.value === p.default ? undefined : input.value, null];
  const raw = input.value.trim();
  if (raw === '') return [undefined, null];
  if (p.type === 'float' || p.type === 'int') {
    const v = Number(raw);
    if (!Number.isFinite(v)) return [null, 'a number'];
    if (p.type === 'int' && !Number.isInteger(v)) return [null, 'a whole number'];
    for (const [b, ok, op] of [[p.gt, v > p.gt, '>'], [p.ge, v >= p.ge, '≥'], [p.lt, v < p.lt, '<'], [p.le, v <= p.le, '≤']]) {
      if (b != null && !ok) return [null, `${op} ${b}`];
    }
    return [v, null];
  }
  if (p.type === 'vector3') {
    const v = raw.split(/[\s,]+/).map(Number);
    if (v.length !== 3 || !v.every(Number.isFinite)) return [null, 'three numbers x,y,z'];
    if (v.every((x) => x === 0)) return [null, 'not the zero vector'];
    return [v, null];
  }
  if (p.type === 'ids') {
    const v = raw.split(/[\s,]+/).map(Number);
    if (!v.every(Number.isInteger)) return [null, 'face ids such as 3,7'];
    return [v, null];
  }
  if (p.pattern && !new RegExp(p.pattern).test(raw)) return [null, `of the form ${p.default}`];
  return [raw, null];
}

/** The fieldset of one kind's parameters; returns {node, read()} where read() gives [params, errors]. */
export function paramsForm(kind) {
  const rows = kind.params.map((p) => {
    const id = `p-${kind.name}-${p.name}`;
    const input = inputFor(p, id);
    const err = el('span', { class: 'field-error', id: `${id}-error`, role: 'alert' });
    const help = el('small', { id: `${id}-help`, text: p.description });
    const unit = p.unit ? el('span', { class: 'unit', text: p.unit }) : null;
    const row = el('div', { class: `field field-${p.type}${p.service_only ? ' service' : ''}` },
      el('label', { for: id, text: label(p.name) }), el('div', { class: 'control' }, input, unit), help, err);
    return { p, input, err, row };
  });
  const basic = rows.filter((r) => !r.p.service_only);
  const service = rows.filter((r) => r.p.service_only);
  const node = el('div', { class: 'params' },
    el('details', { class: 'params-main' }, el('summary', { text: `Parameters (${basic.length}; the defaults shown are used unless you set one)` }),
      el('fieldset', {}, el('legend', { class: 'sr-only', text: `${kind.name} parameters` }), basic.map((r) => r.row))),
    service.length ? el('details', {}, el('summary', { text: 'Service options' }), service.map((r) => r.row)) : null);
  function read() {
    const params = {}; const errors = [];
    for (const r of rows) {
      const [v, e] = readField(r.p, r.input);
      r.err.textContent = e ? `must be ${e}` : '';
      r.input.setAttribute('aria-invalid', e ? 'true' : 'false');
      if (e) { errors.push(`${r.p.name} must be ${e}`); r.row.closest('details').open = true; }
      else if (v !== undefined) params[r.p.name] = v;
    }
    return [params, errors];
  }
  return { node, read };
}
