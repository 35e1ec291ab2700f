// The report's defects as a list of drawable items: boundary loops (edges joined into loops), non-manifold and
// mis-oriented edges, non-manifold vertices, self-intersecting pairs, degenerate and duplicate triangles,
// unmeshed CAD faces (listed: they have no triangles to draw; their holes show as boundary loops).

function loops(loc) {
  // join boundary edges (vertex index pairs) into connected groups by union-find
  const parent = new Map();
  const find = (a) => { while (parent.get(a) !== a) { parent.set(a, parent.get(parent.get(a))); a = parent.get(a); } return a; };
  for (const [a, b] of loc.edges) {
    if (!parent.has(a)) parent.set(a, a);
    if (!parent.has(b)) parent.set(b, b);
    parent.set(find(a), find(b));
  }
  const groups = new Map();
  loc.edges.forEach(([a], i) => {
    const r = find(a);
    if (!groups.has(r)) groups.set(r, []);
    groups.get(r).push(loc.coordinates[i]);
  });
  return [...groups.values()];
}

const seg = (coords) => coords.flat(2);
const len = (coords) => coords.reduce((s, [p, q]) => s + Math.hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]), 0);

/** Items {kind, label, segments?, triangles?, points?} from report.mesh (and report.issues for unmeshed faces). */
export function defectItems(report, corners) {
  const mesh = report.mesh || {};
  const loc = mesh.locations || {};
  const items = [];
  if (loc.boundary_edges?.count) {
    loops(loc.boundary_edges).sort((a, b) => len(b) - len(a)).forEach((c, i) => items.push({
      kind: 'boundary loop', label: `Boundary loop ${i + 1}: ${c.length} edges, ${len(c).toFixed(2)} mm`, segments: seg(c) }));
  }
  const edgeKinds = [['nonmanifold_edges', 'Non-manifold edge'], ['misoriented_edges', 'Mis-oriented edge']];
  for (const [key, name] of edgeKinds) {
    (loc[key]?.coordinates || []).slice(0, 200).forEach((c, i) => items.push({
      kind: name.toLowerCase(), label: `${name} ${i + 1}`, segments: seg([c]) }));
  }
  (loc.nonmanifold_vertices?.coordinates || []).slice(0, 200).forEach((p, i) => items.push({
    kind: 'non-manifold vertex', label: `Non-manifold vertex ${i + 1}`, points: p }));
  for (const [key, name] of [['degenerate_triangles', 'Degenerate triangle'], ['duplicate_triangles', 'Duplicate triangle']]) {
    (loc[key]?.coordinates || []).slice(0, 200).forEach((c, i) => items.push({
      kind: name.toLowerCase(), label: `${name} ${loc[key].triangles[i]}`, triangles: c.flat(), points: c.flat() }));
  }
  (mesh.self_intersections?.examples || []).slice(0, 200).forEach(([a, b]) => {
    if (!corners) return;
    const tri = [...corners(a), ...corners(b)];
    items.push({ kind: 'self-intersection', label: `Self-intersection: triangles ${a} and ${b}`, triangles: tri });
  });
  const unmeshed = (report.issues || []).find((x) => x.code === 'unmeshed_faces');
  for (const f of unmeshed?.face_ids || []) {
    const type = report.faces?.[f]?.surface_type || '';
    items.push({ kind: 'unmeshed face', label: `Unmeshed CAD face ${f}${type ? ` (${type})` : ''}: no triangles` });
  }
  return items;
}

/** All items' geometry merged, for the always-on overlay. */
export function merged(items) {
  const out = { segments: [], triangles: [], points: [] };
  for (const it of items) for (const k of Object.keys(out)) if (it[k]) out[k].push(...it[k]);
  return out;
}
