// supervisor web: draws the cell from its kinematics, live, from the frames of /ws
// (docs/web.md). `window.rtc` exposes what the page shows, for tests and for the console.
import * as THREE from 'three';
import { OrbitControls } from '/vendor/OrbitControls.js';

const token = new URLSearchParams(location.search).get('token');
const withToken = (path) => token ? `${path}?token=${encodeURIComponent(token)}` : path;
const rtc = window.rtc = { frames: 0, hello: null, last: null, drawn: null, estop: null, up: false };

// ---- the 3D view (mm, z up) ----
const view = document.getElementById('view');
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
view.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1b1f24);
scene.add(new THREE.HemisphereLight(0xffffff, 0x334455, 2.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.5);
sun.position.set(300, -400, 800);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(40, 1, 1, 20000);
camera.up.set(0, 0, 1);
const controls = new OrbitControls(camera, renderer.domElement);
let machine = null; // { update(frame) }

function resize() {
  const w = view.clientWidth, h = view.clientHeight;
  renderer.setSize(w, h);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);

const mat = (c) => new THREE.MeshStandardMaterial({ color: c, metalness: 0.3, roughness: 0.6 });
function box(sx, sy, sz, color) {
  const m = new THREE.Mesh(new THREE.BoxGeometry(sx, sy, sz), mat(color));
  scene.add(m);
  return m;
}
// A cylinder from a to b (Vector3), radius r: a link.
function link(r, color) {
  const m = new THREE.Mesh(new THREE.CylinderGeometry(r, r, 1, 16), mat(color));
  scene.add(m);
  m.between = (a, b) => {
    const d = new THREE.Vector3().subVectors(b, a);
    m.position.copy(a).addScaledVector(d, 0.5);
    m.scale.set(1, Math.max(d.length(), 1e-6), 1);
    m.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), d.clone().normalize());
  };
  return m;
}
function ball(r, color) {
  const m = new THREE.Mesh(new THREE.SphereGeometry(r, 24, 16), mat(color));
  scene.add(m);
  return m;
}
// The tool's path: the last points it went through.
const TRAIL = 3000;
const trailGeom = new THREE.BufferGeometry();
trailGeom.setAttribute('position', new THREE.BufferAttribute(new Float32Array(TRAIL * 3), 3));
const trail = new THREE.Line(trailGeom, new THREE.LineBasicMaterial({ color: 0x4fc3f7 }));
trail.frustumCulled = false;
scene.add(trail);
let trailN = 0;
function addTrail(x, y, z) {
  const a = trailGeom.attributes.position;
  if (trailN === TRAIL) { a.array.copyWithin(0, 3); trailN--; }
  a.setXYZ(trailN++, x, y, z);
  a.needsUpdate = true;
  trailGeom.setDrawRange(0, trailN);
}

const V = (x, y, z = 0) => new THREE.Vector3(x, y, z);
const rad = (d) => d * Math.PI / 180;

function frameCamera(cx, cy, size) {
  controls.target.set(cx, cy, 0);
  camera.position.set(cx + size * 0.3, cy - size * 1.3, size * 1.0);
  controls.update();
}

// Each kinematics: build the parts once, then place them from a frame (measured joints, and
// the tool through the kinematics). Returns the tool's drawn position.
const builders = {
  gantry(h) {
    const [ax, ay] = h.axes;
    const w = ax.max - ax.min, d = ay.max - ay.min;
    const base = box(w + 40, d + 40, 6, 0x2c3440);
    base.position.set((ax.min + ax.max) / 2, (ay.min + ay.max) / 2, -3);
    const beam = box(24, d + 40, 16, 0xb0b8c0);
    const carriage = box(36, 36, 24, 0xe0a030);
    const tool = link(4, 0xdddddd);
    const mark = box(3, 18, 3, 0xff5050);
    frameCamera((ax.min + ax.max) / 2, (ay.min + ay.max) / 2, Math.max(w, d));
    return (f) => {
      const [x, y, th = 0] = f.joints;
      beam.position.set(x, (ay.min + ay.max) / 2, 60);
      carriage.position.set(x, y, 60);
      tool.between(V(x, y, 48), V(x, y, 8));
      mark.position.set(x, y, 6);
      mark.rotation.z = rad(th);
      return [x, y];
    };
  },
  scara(h) {
    const l1 = h.params.l1, l2 = h.params.l2;
    const reach = l1 + l2;
    const base = box(60, 60, 40, 0x2c3440); base.position.set(0, 0, 20);
    const a = link(10, 0xb0b8c0), b = link(8, 0xe0a030), j = ball(14, 0x888888), t = ball(8, 0xff5050);
    frameCamera(0, 0, reach * 2);
    return (f) => {
      const q = f.joints, tool = f.tool;
      const e = V(l1 * Math.cos(rad(q[0])), l1 * Math.sin(rad(q[0])), 40);
      const p = V(tool[0], tool[1], 40);
      a.between(V(0, 0, 40), e); b.between(e, p); j.position.copy(e); t.position.copy(p);
      return [tool[0], tool[1]];
    };
  },
  'five-bar'(h) {
    const { l1, l2, l3, l5 } = h.params;
    const base = ball(16, 0x2c3440);
    const c1 = link(7, 0xb0b8c0), c2 = link(7, 0xb0b8c0), d1 = link(5, 0xe0a030), d2 = link(5, 0xe0a030);
    const t = ball(8, 0xff5050);
    frameCamera(0, 0, (l1 + l2) * 2);
    return (f) => {
      const [a0, a1] = f.joints, tool = f.tool;
      const T = V(l1 * Math.cos(rad(a0 + 180)), l1 * Math.sin(rad(a0 + 180)));
      const W = V(l5 * Math.cos(rad(a1 + 270)), l5 * Math.sin(rad(a1 + 270)));
      const P = V(tool[0], tool[1]);
      const E = T.clone().addScaledVector(new THREE.Vector3().subVectors(P, T), l3 / l2);
      c1.between(V(0, 0), T); c2.between(V(0, 0), W); d1.between(T, P); d2.between(W, E);
      base.position.set(0, 0, 0); t.position.copy(P);
      return [tool[0], tool[1]];
    };
  },
  // Any other kinematics: the tool, and a line from the origin to it.
  other(h) {
    const arm = link(5, 0xb0b8c0), t = ball(8, 0xff5050);
    frameCamera(0, 0, 500);
    return (f) => {
      const tool = f.tool || f.joints;
      const p = V(tool[0] || 0, tool[1] || 0, tool.length > 2 && h.kinematics !== 'polar' ? 0 : 0);
      arm.between(V(0, 0), p); t.position.copy(p);
      return [p.x, p.y];
    };
  },
};

function build(h) {
  // A new description (first connection, or the cell came up again): rebuild the scene.
  for (const o of [...scene.children]) if (o.isMesh) scene.remove(o);
  trailN = 0; trailGeom.setDrawRange(0, 0);
  machine = (builders[h.kinematics] || builders.other)(h);
  document.getElementById('legend').textContent =
    `${h.kinematics} · ${h.axes.map(a => `${a.name} [${a.unit}]`).join(', ')} · drag to orbit`;
}

// ---- the side panel and the plots ----
const $ = (id) => document.getElementById(id);
const PLOT_S = 10;
const feHist = [], latHist = [];
const colors = ['#ef5350', '#66bb6a', '#42a5f5', '#ffca28', '#ab47bc', '#26c6da', '#ff7043', '#8d6e63'];
function plot(canvas, hist, title, unit) {
  const w = canvas.width = canvas.clientWidth, h = canvas.height = canvas.clientHeight;
  const g = canvas.getContext('2d');
  g.fillStyle = '#15181c'; g.fillRect(0, 0, w, h);
  g.fillStyle = '#9ab'; g.fillText(title, 8, 14);
  if (hist.length < 2) return;
  const t1 = hist[hist.length - 1].t, t0 = t1 - PLOT_S;
  const n = hist[hist.length - 1].v.length;
  let lo = 0, hi = 0;
  for (const p of hist) for (const v of p.v) { if (v < lo) lo = v; if (v > hi) hi = v; }
  if (hi - lo < 1e-9) hi = lo + 1;
  const X = (t) => 40 + (t - t0) / PLOT_S * (w - 50), Y = (v) => h - 16 - (v - lo) / (hi - lo) * (h - 36);
  g.strokeStyle = '#333'; g.beginPath(); g.moveTo(40, Y(0)); g.lineTo(w - 10, Y(0)); g.stroke();
  g.fillStyle = '#9ab'; g.fillText(`${hi.toPrecision(3)} ${unit}`, 2, 26); g.fillText(`${lo.toPrecision(3)}`, 2, h - 16);
  for (let k = 0; k < n; k++) {
    g.strokeStyle = colors[k % colors.length]; g.beginPath();
    hist.forEach((p, i) => { const x = X(p.t), y = Y(p.v[k] ?? 0); i ? g.lineTo(x, y) : g.moveTo(x, y); });
    g.stroke();
    g.fillStyle = colors[k % colors.length]; g.fillText(hist.names[k] || '', 160 + 70 * k, 14);
  }
}
function keep(hist, t, v, names) {
  hist.push({ t, v }); hist.names = names;
  while (hist.length && hist[0].t < t - PLOT_S) hist.shift();
}

const STATES = ['idle', 'moving', 'done', 'fault'];
const ORIGINS = ['', 'device', 'external', 'host'];
function panel(f) {
  const h = rtc.hello;
  const banner = $('banner');
  if (!f.up) { banner.className = 'down'; banner.textContent = 'cell down: waiting for it'; return; }
  if (f.estop) {
    banner.className = 'bad';
    banner.textContent = `E-STOP (${ORIGINS[f.estop.origin] || f.estop.origin}): ${f.estop.reason}`;
  } else {
    banner.className = 'ok';
    banner.textContent = f.enabled ? 'running: drives enabled' : 'up: drives disabled';
  }
  const p = f.program;
  $('program').textContent = p ? `program ${p.id} line ${p.line}: ${STATES[p.state] || p.state}, ` +
    `${p.motion_time_s.toFixed(2)} s, speed ${(p.path_speed * 100).toFixed(0)} % (override ${(p.speed_override * 100).toFixed(0)} %)` : 'none';
  if (h && f.joints) {
    $('axes').innerHTML = h.axes.map((a, k) =>
      `<tr><td>${a.name}</td><td>${f.joints[k].toFixed(3)} ${a.unit}</td><td>fe ${f.following_error[k].toFixed(4)}</td></tr>`).join('');
  }
  $('processes').innerHTML = '<tr><th>name</th><th>state</th><th>wake µs</th><th>max µs</th><th>overruns</th></tr>' +
    f.processes.map(p => `<tr><td>${p.name}</td><td>${['starting', 'cyclic', 'stopping', 'fault'][p.state] ?? p.state ?? '–'}</td>` +
      `<td>${p.wakeup_us?.toFixed(1) ?? '–'}</td><td>${p.max_wakeup_us?.toFixed(0) ?? '–'}</td><td>${p.overruns ?? '–'}</td></tr>`).join('');
}

// Drawn when something changes (a frame, the camera), not at the display's rate: a
// software-rendered page must not take a CPU from the controller it shows.
let dirty = true;
controls.addEventListener('change', () => { dirty = true; });

function onFrame(f) {
  rtc.frames++; rtc.last = f; rtc.up = f.up; rtc.estop = f.up ? f.estop : null;
  dirty = true;
  panel(f);
  if (!f.up || !machine || !f.joints) return;
  const [x, y] = machine(f);
  rtc.drawn = [x, y];
  if (f.program && f.program.state === 1) addTrail(x, y, 1);
  if (rtc.hello) {
    keep(feHist, f.t, f.following_error, rtc.hello.axes.map(a => a.name));
    keep(latHist, f.t, f.processes.map(p => p.wakeup_us ?? 0), f.processes.map(p => p.name));
  }
}

// ---- the connection: again and again, whatever the cell does ----
function connect() {
  const ws = new WebSocket(withToken(`ws://${location.host}/ws`));
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (m.kind === 'hello') { rtc.hello = m; build(m); } else onFrame(m);
  };
  ws.onclose = () => { rtc.up = false; $('banner').className = 'down'; $('banner').textContent = 'web server unreachable: retrying'; setTimeout(connect, 1000); };
}

async function act(what) {
  $('answer').textContent = `${what}…`;
  try {
    const r = await fetch(withToken(`/api/${what}`), { method: 'POST' });
    $('answer').textContent = await r.text();
  } catch (e) { $('answer').textContent = `${what}: ${e}`; }
}
$('estop').onclick = () => act('estop');
$('reset').onclick = () => act('reset');
$('start').onclick = () => act('start');

resize();
connect();
window.addEventListener('resize', () => { dirty = true; });
(function loop() {
  requestAnimationFrame(loop);
  controls.update();
  if (!dirty) return;
  dirty = false;
  renderer.render(scene, camera);
  plot($('fe'), feHist, 'following error (largest per frame)', 'unit');
  plot($('lat'), latHist, 'wake-up latency', 'µs');
})();
