// Colour maps for per-triangle fields: a perceptually ordered ramp (viridis stops), grey for unknown (NaN).

const VIRIDIS = [[68, 1, 84], [72, 40, 120], [62, 74, 137], [49, 104, 142], [38, 130, 142], [31, 158, 137],
  [53, 183, 121], [109, 205, 89], [180, 222, 44], [253, 231, 37]];
export const BASE = [176, 184, 194];
export const NAN = [150, 150, 150];

export function ramp(x) {
  const t = Math.min(1, Math.max(0, x)) * (VIRIDIS.length - 1);
  const i = Math.min(VIRIDIS.length - 2, Math.floor(t));
  const f = t - i;
  return VIRIDIS[i].map((a, k) => Math.round(a + f * (VIRIDIS[i + 1][k] - a)));
}

export function cssRamp() {
  return `linear-gradient(to right, ${VIRIDIS.map((c) => `rgb(${c})`).join(', ')})`;
}

/** The range [lo, hi] of a field's finite values (hi > lo). */
export function range(values) {
  let lo = Infinity, hi = -Infinity;
  for (const v of values) if (Number.isFinite(v)) { if (v < lo) lo = v; if (v > hi) hi = v; }
  if (!Number.isFinite(lo)) return [0, 1];
  return [Math.min(lo, 0), hi > Math.min(lo, 0) ? hi : Math.min(lo, 0) + 1];
}

/** Per-corner RGB bytes (9m) of m per-triangle values on [lo, hi]; null values → the plain base colour. */
export function fieldColours(count, values, lo, hi) {
  const out = new Uint8Array(9 * count);
  const lut = Array.from({ length: 256 }, (_, i) => ramp(i / 255));
  for (let t = 0; t < count; t++) {
    let c = BASE;
    if (values) {
      const v = values[t];
      c = Number.isFinite(v) ? lut[Math.max(0, Math.min(255, Math.round((255 * (v - lo)) / (hi - lo))))] : NAN;
    }
    const o = 9 * t;
    for (let k = 0; k < 9; k += 3) { out[o + k] = c[0]; out[o + k + 1] = c[1]; out[o + k + 2] = c[2]; }
  }
  return out;
}
