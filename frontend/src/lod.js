// Web worker: a lighter copy of a triangle soup for drawing while the view moves, by vertex clustering on a grid
// (corners in one cell merge at the cell's mean; triangles whose corners fall in fewer than 3 cells vanish).
// In: {positions: Float32Array(9m), target}. Out: {positions, normals: Int8Array, orig: Int32Array (source triangle)}.

function cells(pos, g, lo, inv) {
  const n = pos.length / 3;
  const key = new Int32Array(n);
  for (let i = 0; i < n; i++) {
    const x = Math.min(g - 1, ((pos[3 * i] - lo[0]) * inv) | 0);
    const y = Math.min(g - 1, ((pos[3 * i + 1] - lo[1]) * inv) | 0);
    const z = Math.min(g - 1, ((pos[3 * i + 2] - lo[2]) * inv) | 0);
    key[i] = x + g * (y + g * z);
  }
  return key;
}

function kept(key) {
  const m = key.length / 3;
  const keep = new Uint8Array(m);
  let n = 0;
  for (let t = 0; t < m; t++) {
    const a = key[3 * t], b = key[3 * t + 1], c = key[3 * t + 2];
    if (a !== b && b !== c && a !== c) { keep[t] = 1; n += 1; }
  }
  return [keep, n];
}

function simplify(pos, target) {
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < pos.length; i += 3) {
    for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], pos[i + k]); hi[k] = Math.max(hi[k], pos[i + k]); }
  }
  const extent = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;
  let g = 128, key, keep, n;
  for (let round = 0; round < 6; round++) {
    key = cells(pos, g, lo, (g / extent) * 0.999999);
    [keep, n] = kept(key);
    if ((n <= target && n >= 0.6 * target) || (n > target && g <= 8) || (n < target && g >= 1024)) break;
    const next = Math.round(g * Math.sqrt(target / Math.max(n, 1)) * (n > target ? 0.97 : 1));
    g = Math.max(8, Math.min(1024, next === g ? g + (n > target ? -1 : 1) : next));
  }
  const sum = new Map();
  for (let i = 0; i < key.length; i++) {
    let s = sum.get(key[i]);
    if (!s) { s = [0, 0, 0, 0]; sum.set(key[i], s); }
    s[0] += pos[3 * i]; s[1] += pos[3 * i + 1]; s[2] += pos[3 * i + 2]; s[3] += 1;
  }
  const out = new Float32Array(9 * n);
  const orig = new Int32Array(n);
  for (let t = 0, j = 0; t < keep.length; t++) {
    if (!keep[t]) continue;
    orig[j] = t;
    for (let c = 0; c < 3; c++) {
      const s = sum.get(key[3 * t + c]);
      out[9 * j + 3 * c] = s[0] / s[3]; out[9 * j + 3 * c + 1] = s[1] / s[3]; out[9 * j + 3 * c + 2] = s[2] / s[3];
    }
    j += 1;
  }
  return { positions: out, orig };
}

self.onmessage = (e) => {
  const { positions, orig } = simplify(e.data.positions, e.data.target);
  self.postMessage({ positions, orig }, [positions.buffer, orig.buffer]);
};
