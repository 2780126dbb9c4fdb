// texsyn report viewer: source of viewer.bundle.js (built by scripts/vendor-three; do not
// edit the bundle by hand).
//
// Contract with the page written by `texsyn report`:
//   <script type="application/octet-stream" id="ID">BASE64 of a .glb</script>
//   <div class="texsyn-viewer"
//        data-models='[{"label":"textured","data":"ID1","up":[0,0,1]},{"label":"patches","data":"ID2"}]'></div>
//   ("up", optional: the model's up direction, turned onto the view's +Y)
// Every .texsyn-viewer gets a toolbar (one toggle button per model when there are several,
// and "reset view") and a WebGL canvas with orbit controls. A viewer is mounted when it first
// comes near the viewport (so viewers inside closed <details> cost nothing until opened), and
// a model is decoded the first time it is shown. At most MAX_LIVE WebGL contexts are kept:
// browsers cap them (~16), so the least recently seen off-screen viewer gives its context
// back and is re-created when scrolled to again.
//
// Status for tests: window.texsynViewers[i] = {loaded, error, model, models: [{label, loaded,
// error}]} in document order; `loaded`/`error` describe the model currently selected.
import {
  AmbientLight,
  Box3,
  Color,
  DirectionalLight,
  PerspectiveCamera,
  Scene,
  Sphere,
  Vector3,
  WebGLRenderer,
} from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const BACKGROUND = 0xe8e8e8;
const MAX_LIVE = 8;
// Direction from the model's centre to the camera in the initial view.
const VIEW_DIR = new Vector3(0.55, 0.45, 1).normalize();

const CSS = `
.texsyn-viewer { position: relative; font: 13px system-ui, sans-serif; }
.texsyn-viewer-bar { display: flex; flex-wrap: wrap; gap: 4px; margin: 0 0 4px; }
.texsyn-viewer-bar button { font: inherit; padding: 2px 10px; border: 1px solid #999;
  border-radius: 3px; background: #f6f6f6; cursor: pointer; }
.texsyn-viewer-bar button[aria-pressed="true"] { background: #333; color: #fff; border-color: #333; }
.texsyn-viewer-reset { margin-left: auto; }
.texsyn-viewer-stage { position: relative; height: var(--texsyn-viewer-height, 480px);
  background: #e8e8e8; overflow: hidden; }
.texsyn-viewer-stage canvas, .texsyn-viewer-snapshot { display: block; width: 100%; height: 100%;
  touch-action: none; }
.texsyn-viewer-status { position: absolute; left: 8px; top: 8px; color: #444; pointer-events: none;
  white-space: pre-wrap; }
.texsyn-viewer-status.texsyn-viewer-error { color: #b00020; font-weight: 600; }
`;

/** Decodes the base64 text of a <script type="application/octet-stream"> into an ArrayBuffer. */
function decodeBase64(text) {
  if (typeof Uint8Array.fromBase64 === 'function') {
    return Uint8Array.fromBase64(text.trim()).buffer; // skips ASCII whitespace
  }
  const bin = atob(text); // forgiving-base64: whitespace removed
  const out = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
  return out.buffer;
}

function modelBytes(id) {
  const el = document.getElementById(id);
  if (!el) throw new Error(`no element with id "${id}" holds the model`);
  return decodeBase64(el.textContent);
}

const live = []; // viewers holding a WebGL context, least recently visible first

/** A model's `up` ([x, y, z], optional) as a unit vector, or null when absent or unusable. */
function upOf(up) {
  if (!Array.isArray(up) || up.length !== 3 || !up.every(Number.isFinite)) return null;
  const v = new Vector3(up[0], up[1], up[2]);
  return v.lengthSq() > 0 ? v.normalize() : null;
}

class Viewer {
  constructor(el, index) {
    this.el = el;
    this.status = { loaded: false, error: null, model: null, models: [] };
    this.visible = false;
    this.renderer = null;
    this.controls = null;
    this.current = -1;
    this.models = [];
    this.pending = false;

    let list;
    try {
      list = JSON.parse(el.dataset.models || '[]');
      if (!Array.isArray(list) || list.length === 0) throw new Error('data-models is empty');
    } catch (e) {
      list = [];
      this.buildDom();
      this.fail(`viewer ${index}: bad data-models: ${e.message}`);
      return;
    }
    this.models = list.map((m) => ({ label: String(m.label ?? m.data), data: String(m.data),
      up: upOf(m.up), object: null, box: null, sphere: null, promise: null, error: null }));
    this.status.models = this.models.map((m) => ({ label: m.label, loaded: false, error: null }));
    this.index = index;

    this.scene = new Scene();
    this.scene.background = new Color(BACKGROUND);
    this.camera = new PerspectiveCamera(35, 1, 0.01, 100);
    this.scene.add(this.camera);
    this.scene.add(new AmbientLight(0xffffff, 0.5));
    // A head light, above and left of the eye, so the lit side always faces the viewer.
    const sun = new DirectionalLight(0xffffff, 2.0);
    sun.position.set(-0.5, 1, 0.6);
    this.camera.add(sun);
    this.camera.add(sun.target);
    sun.target.position.set(0, 0, -1);

    this.buildDom();
    this.select(0);
  }

  buildDom() {
    const el = this.el;
    el.textContent = '';
    const bar = document.createElement('div');
    bar.className = 'texsyn-viewer-bar';
    this.buttons = this.models.length > 1 ? this.models.map((m, i) => {
      const b = document.createElement('button');
      b.type = 'button';
      b.className = 'texsyn-viewer-toggle';
      b.textContent = m.label;
      b.setAttribute('aria-pressed', 'false');
      b.addEventListener('click', () => this.select(i));
      bar.appendChild(b);
      return b;
    }) : [];
    const reset = document.createElement('button');
    reset.type = 'button';
    reset.className = 'texsyn-viewer-reset';
    reset.textContent = 'reset view';
    reset.addEventListener('click', () => { this.frame(); this.requestRender(); });
    bar.appendChild(reset);
    this.stage = document.createElement('div');
    this.stage.className = 'texsyn-viewer-stage';
    this.statusEl = document.createElement('div');
    this.statusEl.className = 'texsyn-viewer-status';
    this.stage.appendChild(this.statusEl);
    el.append(bar, this.stage);
  }

  showStatus(text, isError) {
    this.statusEl.textContent = text;
    this.statusEl.classList.toggle('texsyn-viewer-error', !!isError);
  }

  fail(message) {
    this.status.loaded = false;
    this.status.error = message;
    this.showStatus(`Could not show the model: ${message}`, true);
    console.error(`texsyn viewer: ${message}`);
  }

  /** Shows model i (decoding it on first use) once the viewer is mounted. */
  select(i) {
    this.current = i;
    const m = this.models[i];
    this.status.model = m.label;
    this.status.loaded = false;
    this.status.error = null;
    this.buttons.forEach((b, j) => b.setAttribute('aria-pressed', String(i === j)));
    if (this.renderer) this.show();
  }

  /** Called when the viewer is visible: makes sure it has a context and shows its model. */
  mount() {
    if (!this.renderer) {
      if (!this.createRenderer()) return;
    }
    touch(this);
    this.show();
  }

  createRenderer() {
    while (live.length >= MAX_LIVE) {
      const victim = live.find((v) => !v.visible) || live[0];
      victim.release();
    }
    let renderer;
    try {
      renderer = new WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    } catch (e) {
      this.fail(`WebGL is not available (${e.message})`);
      return false;
    }
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer = renderer;
    if (this.snapshot) { this.snapshot.remove(); this.snapshot = null; }
    this.stage.insertBefore(renderer.domElement, this.statusEl);
    this.controls = new OrbitControls(this.camera, renderer.domElement);
    if (this.savedTarget) this.controls.target.copy(this.savedTarget);
    this.controls.addEventListener('change', () => this.requestRender());
    this.controls.addEventListener('start', () => { this.userMoved = true; });
    this.resizeObserver = new ResizeObserver(() => this.resize());
    this.resizeObserver.observe(this.stage);
    this.resize();
    live.push(this);
    return true;
  }

  /** Gives the WebGL context back (the decoded models and camera are kept). */
  release() {
    const i = live.indexOf(this);
    if (i >= 0) live.splice(i, 1);
    if (!this.renderer) return;
    this.savedTarget = this.controls.target.clone();
    // Leave the last picture in place of the canvas (e.g. for a full-page screenshot).
    this.snapshot = document.createElement('img');
    this.snapshot.className = 'texsyn-viewer-snapshot';
    this.snapshot.alt = '';
    this.snapshot.src = this.renderer.domElement.toDataURL();
    this.stage.insertBefore(this.snapshot, this.statusEl);
    this.resizeObserver.disconnect();
    this.controls.dispose();
    this.renderer.dispose();
    this.renderer.forceContextLoss();
    this.renderer.domElement.remove();
    this.renderer = null;
    this.controls = null;
  }

  resize() {
    if (!this.renderer) return;
    const w = this.stage.clientWidth;
    const h = this.stage.clientHeight;
    if (w === 0 || h === 0) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    if (!this.userMoved) this.frame(); // refit to the new shape unless the user moved the view
    this.render();
  }

  requestRender() {
    if (this.pending || !this.renderer) return;
    this.pending = true;
    requestAnimationFrame(() => { this.pending = false; this.render(); });
  }

  render() {
    if (this.renderer) this.renderer.render(this.scene, this.camera);
  }

  load(m, i) {
    if (!m.promise) {
      // Yield first so the page paints "loading" before a large model is decoded.
      m.promise = new Promise((r) => setTimeout(r, 0))
        .then(() => new GLTFLoader().parseAsync(modelBytes(m.data), ''))
        .then((gltf) => {
          m.object = gltf.scene;
          // Stand the model up: its up direction (the one texsyn's previews use) onto +Y.
          if (m.up) {
            m.object.quaternion.setFromUnitVectors(m.up, new Vector3(0, 1, 0));
            m.object.updateMatrixWorld(true);
          }
          m.box = new Box3().setFromObject(m.object);
          m.sphere = m.box.getBoundingSphere(new Sphere());
          if (!(m.sphere.radius > 0) || !Number.isFinite(m.sphere.radius)) {
            throw new Error('the model is empty');
          }
          this.status.models[i].loaded = true;
        })
        .catch((e) => {
          m.error = `model "${m.label}": ${e && e.message ? e.message : e}`;
          this.status.models[i].error = m.error;
        });
    }
    return m.promise;
  }

  show() {
    const i = this.current;
    const m = this.models[i];
    if (!m.object && !m.error) this.showStatus(`loading ${m.label}…`);
    this.load(m, i).then(() => {
      if (this.current !== i || !this.renderer) return; // superseded or released meanwhile
      if (m.error) { this.fail(m.error); return; }
      if (this.shown !== m) {
        const prev = this.shown;
        if (prev) this.scene.remove(prev.object);
        this.scene.add(m.object);
        this.shown = m;
        // Keep the camera when switching between views of the same mesh.
        if (!prev || !similar(prev.sphere, m.sphere)) this.frame();
      }
      this.showStatus('');
      this.render();
      this.status.loaded = true;
      this.status.error = null;
    });
  }

  /**
   * Frames the shown model from VIEW_DIR: the orbit target is its bounding sphere's centre and
   * the camera is moved back until its bounding box fits the view.
   */
  frame() {
    if (!this.shown) return;
    this.userMoved = false;
    const { sphere, box } = this.shown;
    const center = sphere.center;
    const cam = this.camera;
    const tanV = Math.tan((cam.fov * Math.PI) / 360);
    const tanH = tanV * cam.aspect;
    const right = new Vector3(0, 1, 0).cross(VIEW_DIR).normalize();
    const up = VIEW_DIR.clone().cross(right);
    let dist = 0;
    const c = new Vector3();
    for (let k = 0; k < 8; k++) {
      c.set(k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y, k & 4 ? box.max.z : box.min.z)
        .sub(center);
      const depth = c.dot(VIEW_DIR);
      dist = Math.max(dist, depth + Math.abs(c.dot(right)) / tanH, depth + Math.abs(c.dot(up)) / tanV);
    }
    dist = Math.max(dist * 1.08, sphere.radius * 1.2);
    cam.up.set(0, 1, 0);
    cam.position.copy(center).addScaledVector(VIEW_DIR, dist);
    cam.near = sphere.radius * 0.002;
    cam.far = dist * 12 + sphere.radius * 2;
    cam.updateProjectionMatrix();
    if (this.controls) {
      this.controls.target.copy(center);
      this.controls.maxDistance = dist * 10;
      this.controls.update();
    } else {
      this.savedTarget = center.clone();
      cam.lookAt(center);
    }
  }
}

function similar(a, b) {
  return a.center.distanceTo(b.center) < 0.25 * a.radius &&
    b.radius < 1.5 * a.radius && a.radius < 1.5 * b.radius;
}

function touch(v) {
  const i = live.indexOf(v);
  if (i >= 0) { live.splice(i, 1); live.push(v); }
}

function init() {
  if (!document.getElementById('texsyn-viewer-style')) {
    const style = document.createElement('style');
    style.id = 'texsyn-viewer-style';
    style.textContent = CSS;
    document.head.appendChild(style);
  }
  const viewers = [];
  window.texsynViewers = [];
  document.querySelectorAll('.texsyn-viewer').forEach((el, i) => {
    const v = new Viewer(el, i);
    viewers.push(v);
    window.texsynViewers.push(v.status);
  });
  const mountable = viewers.filter((v) => v.models.length > 0);
  if (typeof IntersectionObserver !== 'function') {
    mountable.forEach((v) => { v.visible = true; v.mount(); });
    return;
  }
  const byEl = new Map(mountable.map((v) => [v.el, v]));
  const io = new IntersectionObserver((entries) => {
    for (const e of entries) {
      const v = byEl.get(e.target);
      v.visible = e.isIntersecting;
      if (v.visible) v.mount();
    }
  }, { rootMargin: '200px' });
  mountable.forEach((v) => io.observe(v.el));
}

if (document.readyState === 'loading') {
  document.addEventListener('DOMContentLoaded', init);
} else {
  init();
}
