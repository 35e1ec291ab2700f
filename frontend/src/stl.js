// STL bytes → flat triangle arrays for the viewer: positions (9m float32) and per-corner flat normals (9m int8).

/** True when the bytes are a binary STL: 84 + 50·n bytes for the n its header declares. */
export function isBinary(buffer) {
  if (buffer.byteLength < 84) return false;
  const n = new DataView(buffer).getUint32(80, true);
  return 84 + 50 * n === buffer.byteLength;
}

/** Flat per-corner normals (9m int8, ×127) of a triangle soup's positions (9m). */
export function normals(pos) {
  const m = pos.length / 9;
  const nrm = new Int8Array(pos.length);
  for (let t = 0; t < m; t++) {
    const o = 9 * t;
    const ux = pos[o + 3] - pos[o], uy = pos[o + 4] - pos[o + 1], uz = pos[o + 5] - pos[o + 2];
    const vx = pos[o + 6] - pos[o], vy = pos[o + 7] - pos[o + 1], vz = pos[o + 8] - pos[o + 2];
    let nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const len = Math.hypot(nx, ny, nz) || 1;
    nx = Math.round((127 * nx) / len); ny = Math.round((127 * ny) / len); nz = Math.round((127 * nz) / len);
    for (let k = 0; k < 9; k += 3) { nrm[o + k] = nx; nrm[o + k + 1] = ny; nrm[o + k + 2] = nz; }
  }
  return nrm;
}

function binary(buffer) {
  const dv = new DataView(buffer);
  const m = dv.getUint32(80, true);
  const pos = new Float32Array(9 * m);
  for (let t = 0, at = 84; t < m; t++, at += 50) {
    for (let k = 0; k < 9; k++) pos[9 * t + k] = dv.getFloat32(at + 12 + 4 * k, true);
  }
  return pos;
}

function ascii(buffer) {
  const text = new TextDecoder().decode(buffer);
  const re = /vertex\s+(\S+)\s+(\S+)\s+(\S+)/g;
  const out = [];
  let m;
  while ((m = re.exec(text)) !== null) out.push(+m[1], +m[2], +m[3]);
  return new Float32Array(out.slice(0, out.length - (out.length % 9)));
}

/** {positions, normals, count} of an STL's triangles, in the file's order (triangle i ↔ field value i). */
export function parseSTL(buffer) {
  const positions = isBinary(buffer) ? binary(buffer) : ascii(buffer);
  return { positions, normals: normals(positions), count: positions.length / 9 };
}
