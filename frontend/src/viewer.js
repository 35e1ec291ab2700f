// The 3D view: one triangle soup (non-indexed, flat normals, per-corner colours) drawn on demand with a headlight,
// orbit / pan / zoom, fit, wireframe, defect overlays, a highlighted selection and triangle picking. A mesh whose
// full frame takes longer than FRAME_MS is drawn from a lighter copy (lod.js, in a worker) while the view moves,
// and in full as soon as it stops.

import {
  BufferAttribute, BufferGeometry, Box3, Color, Float32BufferAttribute, LineBasicMaterial, LineSegments, Mesh,
  MeshBasicMaterial, PerspectiveCamera, Points, PointsMaterial, Raycaster, Scene, ShaderMaterial, Sphere, Vector2,
  Vector3, WebGLRenderer, DoubleSide,
} from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { BASE, fieldColours } from './colours.js';
import { normals } from './stl.js';

export const HIGHLIGHT = 0xffd400;
export const FRAME_MS = 30;  // a full frame slower than this gets a moving copy sized to draw within it
const SETTLE_MS = 180;  // the full mesh is drawn again this long after the last move
export const DEFECT = 0xd0021b;

// Lambert shading by a light at the eye, computed per vertex: the cheapest shading that still shows the shape,
// which keeps a million triangles turning on a software renderer.
const VERTEX = `
attribute vec3 color;
varying vec3 vColour;
void main() {
  vec3 n = normalize(normalMatrix * normal);
  float l = 0.4 + 0.6 * abs(n.z);
  vColour = color * l;
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`;
const FRAGMENT = `
varying vec3 vColour;
void main() { gl_FragColor = vec4(vColour, 1.0); }`;

export class Viewer {
  constructor(container, caption = '') {
    this.container = container;
    this.renderer = new WebGLRenderer({ antialias: false, powerPreference: 'high-performance' });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 1.5));
    this.renderer.setClearColor(new Color(0xe9edf2));
    const canvas = this.renderer.domElement;
    canvas.tabIndex = 0;
    canvas.setAttribute('role', 'img');
    canvas.setAttribute('aria-label', `3D view${caption ? ` of ${caption}` : ''}: drag to turn, right-drag or shift-drag to `
      + 'pan, wheel to zoom; keys: arrows turn, + and − zoom, f fits, w toggles wireframe');
    container.append(canvas);
    if (caption) container.append(Object.assign(document.createElement('span'), { className: 'caption', textContent: caption }));
    this.scene = new Scene();
    this.camera = new PerspectiveCamera(35, 1, 0.1, 1000);
    this.camera.up.set(0, 0, 1);  // CAD parts are modelled z-up
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener('change', () => { this.moved(); this.onView?.(this); });
    this.overlay = [];
    this.frames = 0;
    this.pending = false;
    const forced = Number(new URLSearchParams(location.search).get('frame_ms'));  // ?frame_ms=N: another budget
    this.frameMs = Number.isFinite(forced) && forced > 0 ? forced : undefined;
    new ResizeObserver(() => this.resize()).observe(container);
    canvas.addEventListener('keydown', (e) => this.key(e));
    this.resize();
  }

  resize() {
    const w = this.container.clientWidth || 1, h = this.container.clientHeight || 1;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.request();
  }

  request() {
    if (this.pending || this.spinning) return;
    this.pending = true;
    requestAnimationFrame(() => { this.pending = false; this.draw(); });
  }

  draw() {
    const light = this.lod && this.moving;
    if (this.lod) { this.mesh.visible = !light; this.lod.visible = light; }
    this.renderer.render(this.scene, this.camera);
    this.frames += 1;
    this.onDraw?.(this);
  }

  /** The view moved: draw the light copy now, the full mesh once it has settled. */
  moved() {
    this.moving = true;
    clearTimeout(this.settle);
    this.settle = setTimeout(() => { this.moving = false; this.request(); }, SETTLE_MS);
    this.request();
  }

  /** Time full frames as the screen shows them (rAF to rAF, three in a row); when one takes over FRAME_MS, build
   * the moving copy in a worker, sized so a frame of it should fit in FRAME_MS. */
  async timeFrame() {
    const gl = this.renderer.getContext();
    const frame = () => new Promise((r) => requestAnimationFrame(() => {
      this.renderer.render(this.scene, this.camera);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
      r(performance.now());
    }));
    const t0 = await frame();
    let t = t0;
    for (let k = 0; k < 3; k++) t = await frame();
    this.fullMs = (t - t0) / 3;
    const budget = this.frameMs ?? FRAME_MS;
    if (this.fullMs <= budget || this.count < 20000) return null;
    const target = Math.max(5000, Math.floor((this.count * budget * 0.7) / Math.max(this.fullMs, 1e-3)));
    const positions = this.mesh.geometry.getAttribute('position').array.slice();
    return new Promise((resolve) => {
      const worker = new Worker(new URL('./lod.js', import.meta.url), { type: 'module' });
      worker.onmessage = (e) => { worker.terminate(); this.setLod(e.data); resolve(this.lod); };
      worker.onerror = () => { worker.terminate(); resolve(null); };
      worker.postMessage({ positions, target }, [positions.buffer]);
    });
  }

  setLod({ positions, orig }) {
    const g = new BufferGeometry();
    g.setAttribute('position', new BufferAttribute(positions, 3));
    g.setAttribute('normal', new BufferAttribute(normals(positions), 3, true));
    g.setAttribute('color', new BufferAttribute(new Uint8Array(positions.length), 3, true));
    g.computeBoundingSphere();
    this.lodOrig = orig;
    this.lod = new Mesh(g, this.material);
    this.lod.visible = false;
    this.scene.add(this.lod);
    this.copyColours();
    this.container.dataset.moving = String(orig.length);
  }

  copyColours() {  // the moving copy's corners take the colours of the triangles they came from
    if (!this.lod) return;
    const src = this.mesh.geometry.getAttribute('color').array;
    const dst = this.lod.geometry.getAttribute('color');
    for (let j = 0; j < this.lodOrig.length; j++) dst.array.set(src.subarray(9 * this.lodOrig[j], 9 * this.lodOrig[j] + 9), 9 * j);
    dst.needsUpdate = true;
  }

  /** Show an STL parsed by stl.parseSTL; the camera fits it. */
  setMesh(parsed) {
    const g = new BufferGeometry();
    g.setAttribute('position', new BufferAttribute(parsed.positions, 3));
    g.setAttribute('normal', new BufferAttribute(parsed.normals, 3, true));
    g.setAttribute('color', new BufferAttribute(fieldColours(parsed.count, null), 3, true));
    g.computeBoundingBox();
    g.computeBoundingSphere();
    this.count = parsed.count;
    this.material = new ShaderMaterial({ vertexShader: VERTEX, fragmentShader: FRAGMENT, side: DoubleSide,
      polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1 });
    this.mesh = new Mesh(g, this.material);
    this.scene.add(this.mesh);
    this.fit();
    this.container.dataset.triangles = String(parsed.count);
  }

  /** Colour by per-triangle values on [lo, hi] (null: the plain colour). */
  colourBy(values, lo = 0, hi = 1) {
    const attr = this.mesh.geometry.getAttribute('color');
    attr.array.set(fieldColours(this.count, values, lo, hi));
    attr.needsUpdate = true;
    this.copyColours();
    this.request();
  }

  setWireframe(on) { this.material.wireframe = on; this.request(); }

  /** Frame a box (default: the whole mesh) with a margin. */
  fit(box = this.mesh.geometry.boundingBox, margin = 1.0) {
    const sphere = box.getBoundingSphere(new Sphere());
    const r = Math.max(sphere.radius, 1e-3);
    const dist = (r * margin) / Math.sin((this.camera.fov * Math.PI) / 360) / Math.min(1, this.camera.aspect);
    const dir = this.camera.position.clone().sub(this.controls.target);
    if (dir.lengthSq() === 0 || !Number.isFinite(dir.lengthSq())) dir.set(1, -1.4, 0.9);
    this.controls.target.copy(sphere.center);
    this.camera.position.copy(sphere.center).add(dir.normalize().multiplyScalar(dist));
    const whole = this.mesh.geometry.boundingSphere.radius;
    this.camera.near = Math.max(dist - 2 * whole - r, dist / 1000, 1e-4);
    this.camera.far = dist + 2 * whole + r;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.request();
  }

  clearOverlay(tag) {
    for (const o of this.overlay.filter((x) => x.userData.tag === tag)) { this.scene.remove(o); o.geometry.dispose(); }
    this.overlay = this.overlay.filter((x) => x.userData.tag !== tag);
  }

  /** Draw segments (6 floats each), triangles (9 floats each) and points (3 floats each) under `tag`. */
  draw_overlay(tag, { segments, triangles, points }, colour, onTop = false) {
    this.clearOverlay(tag);
    const add = (obj) => {
      obj.userData.tag = tag;
      obj.renderOrder = onTop ? 10 : 1;
      if (onTop) obj.material.depthTest = false;
      this.overlay.push(obj); this.scene.add(obj);
    };
    const geo = (arr) => { const g = new BufferGeometry(); g.setAttribute('position', new Float32BufferAttribute(arr, 3)); return g; };
    if (segments?.length) add(new LineSegments(geo(segments), new LineBasicMaterial({ color: colour })));
    if (triangles?.length) add(new Mesh(geo(triangles), new MeshBasicMaterial({ color: colour, side: DoubleSide })));
    if (points?.length) add(new Points(geo(points), new PointsMaterial({ color: colour, size: onTop ? 9 : 6, sizeAttenuation: false })));
    this.request();
  }

  /** The index of the triangle under a client-space point, or -1. */
  pick(clientX, clientY) {
    const rect = this.renderer.domElement.getBoundingClientRect();
    const ndc = new Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    const ray = new Raycaster();
    ray.setFromCamera(ndc, this.camera);
    const hit = ray.intersectObject(this.mesh, false)[0];
    return hit ? hit.faceIndex : -1;
  }

  /** The corners (9 floats) of triangle t. */
  corners(t) { return this.mesh.geometry.getAttribute('position').array.slice(9 * t, 9 * t + 9); }

  key(e) {
    const c = this.controls, step = Math.PI / 24;
    const actions = {
      ArrowLeft: () => rotate(this, step, 0), ArrowRight: () => rotate(this, -step, 0),
      ArrowUp: () => rotate(this, 0, step), ArrowDown: () => rotate(this, 0, -step),
      '+': () => zoom(this, 0.8), '=': () => zoom(this, 0.8), '-': () => zoom(this, 1.25),
      f: () => this.fit(), w: () => { this.setWireframe(!this.material.wireframe); this.onWireframe?.(this.material.wireframe); },
    };
    if (actions[e.key]) { e.preventDefault(); actions[e.key](); c.update(); }
  }

  /** Turn continuously for `seconds` as a user's drag does (the moving copy when there is one, or the full mesh
   * with `full`); resolves with the frames per second drawn, each finished before the next (bench/dashboard.py). */
  spin(seconds, full = false) {
    return new Promise((resolve) => {
      const t0 = performance.now(); let frames = 0;
      const gl = this.renderer.getContext();
      this.spinning = true;
      const step = () => {
        rotate(this, 0.02, 0);
        this.controls.update();
        this.moving = !full;
        this.draw();
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
        frames += 1;
        const dt = (performance.now() - t0) / 1000;
        if (dt < seconds) { requestAnimationFrame(step); return; }
        this.spinning = false; this.moving = false; this.request(); resolve(frames / dt);
      };
      requestAnimationFrame(step);
    });
  }

  /** Follow another viewer's camera (before/after side by side). */
  link(other) {
    let busy = false;
    const follow = (src, dst) => () => {
      if (busy) return; busy = true;
      dst.camera.position.copy(src.camera.position); dst.controls.target.copy(src.controls.target);
      dst.camera.near = src.camera.near; dst.camera.far = src.camera.far; dst.camera.updateProjectionMatrix();
      dst.controls.update(); busy = false;
    };
    this.controls.addEventListener('change', follow(this, other));
    other.controls.addEventListener('change', follow(other, this));
  }
}

function rotate(v, dTheta, dPhi) {
  const offset = v.camera.position.clone().sub(v.controls.target);
  const up = v.camera.up.clone().normalize();
  offset.applyAxisAngle(up, dTheta);
  const side = new Vector3().crossVectors(up, offset).normalize();
  if (dPhi) offset.applyAxisAngle(side, dPhi);
  v.camera.position.copy(v.controls.target).add(offset);
  v.camera.lookAt(v.controls.target);
  v.moved();
}

function zoom(v, f) {
  const offset = v.camera.position.clone().sub(v.controls.target).multiplyScalar(f);
  v.camera.position.copy(v.controls.target).add(offset);
  v.moved();
}

export { Box3, Vector3, BASE };
