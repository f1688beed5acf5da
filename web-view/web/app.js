// supervisor web: draws the cell from its kinematics, live, from the frames of /ws
// (docs/web.md). `window.rtc` exposes what the page shows, for tests and for the console.
import * as THREE from 'three';
import { OrbitControls } from '/vendor/OrbitControls.js';

// `?token=` when the server needs one; `?cell=NAME` for a cell of a line (`supervisor web
// --line`), whose page without it lists the line's cells.
const params = new URLSearchParams(location.search);
const token = params.get('token');
const cellName = params.get('cell');
const query = (cell) => {
  const q = new URLSearchParams();
  if (token) q.set('token', token);
  if (cell) q.set('cell', cell);
  const s = q.toString();
  return s ? `?${s}` : '';
};
const withToken = (path) => `${path}${query(cellName)}`;
const rtc = window.rtc = {
  frames: 0, hello: null, last: null, drawn: null, estop: null, up: false, cells: null,
  // The plots' data: the current program's commanded and measured tool path, each process'
  // latency histogram; and what the plots last drew.
  path: { program: null, commanded: [], measured: [] }, latency: [], plotted: {},
};

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
const feHist = [];
const colors = ['#42a5f5', '#ffa726', '#66bb6a', '#ef5350', '#ab47bc', '#8d6e63', '#ec407a', '#bdbdbd'];
// A canvas at its displayed size, cleared, its title written; null when it has no room.
function surface(canvas, title) {
  const w = canvas.width = canvas.clientWidth, h = canvas.height = canvas.clientHeight;
  if (w < 20 || h < 20) return null;
  const g = canvas.getContext('2d');
  g.fillStyle = '#15181c'; g.fillRect(0, 0, w, h);
  g.font = '11px system-ui, sans-serif';
  g.fillStyle = '#9ab'; g.fillText(title, 8, 14);
  return { g, w, h };
}
// Following error per axis, the last PLOT_S seconds (the largest in each frame).
function plotSeries(canvas, hist, title, unit) {
  const s = surface(canvas, title);
  if (!s || hist.length < 2) return;
  const { g, w, h } = s;
  const t1 = hist[hist.length - 1].t, t0 = t1 - PLOT_S;
  const n = hist[hist.length - 1].v.length;
  let lo = 0, hi = 0;
  for (const p of hist) for (const v of p.v) { if (v < lo) lo = v; if (v > hi) hi = v; }
  if (hi - lo < 1e-9) hi = lo + 1;
  const X = (t) => 40 + (t - t0) / PLOT_S * (w - 50), Y = (v) => h - 16 - (v - lo) / (hi - lo) * (h - 36);
  g.strokeStyle = '#333'; g.beginPath(); g.moveTo(40, Y(0)); g.lineTo(w - 10, Y(0)); g.stroke();
  g.fillStyle = '#9ab'; g.fillText(`${hi.toPrecision(3)} ${unit}`, 2, 30); g.fillText(`${lo.toPrecision(3)}`, 2, h - 16);
  for (let k = 0; k < n; k++) {
    g.strokeStyle = colors[k % colors.length]; g.beginPath();
    hist.forEach((p, i) => { const x = X(p.t), y = Y(p.v[k] ?? 0); i ? g.lineTo(x, y) : g.moveTo(x, y); });
    g.stroke();
    g.fillStyle = colors[k % colors.length]; g.fillText(hist.names[k] || '', w - 40 * (n - k), 14);
  }
}
function keep(hist, t, v, names) {
  hist.push({ t, v }); hist.names = names;
  while (hist.length && hist[0].t < t - PLOT_S) hist.shift();
}
// The program's tool path, commanded (wide) and measured (thin), at the same scale on both
// axes, as `supervisor run --plot` draws it.
function plotPath(canvas) {
  const s = surface(canvas, 'path');
  rtc.plotted.path = 0;
  const { commanded: c, measured: m } = rtc.path;
  if (!s || c.length < 2) return;
  const { g, w, h } = s;
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (const [x, y] of c.concat(m)) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
  const span = Math.max(x1 - x0, y1 - y0, 1e-3);
  const k = Math.min((w - 60) / Math.max(x1 - x0, span * 0.05), (h - 40) / Math.max(y1 - y0, span * 0.05));
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  const X = (x) => w / 2 + 10 + (x - cx) * k, Y = (y) => h / 2 + 8 - (y - cy) * k;
  const line = (pts, color, width) => {
    g.strokeStyle = color; g.lineWidth = width; g.beginPath();
    pts.forEach(([x, y], i) => (i ? g.lineTo(X(x), Y(y)) : g.moveTo(X(x), Y(y))));
    g.stroke();
  };
  line(c, colors[0], 5);
  line(m, colors[1], 1.5);
  g.lineWidth = 1;
  g.fillStyle = colors[0]; g.fillText('commanded', w - 130, 14);
  g.fillStyle = colors[1]; g.fillText('measured', w - 60, 14);
  // The tool's coordinates, as the kinematics names them (a joint's unit is not the tool's).
  const [cx0, cy0] = rtc.hello?.coords ?? [];
  const name = (c, d) => (c ? `${c.name}` : d), unit = (c) => (c ? ` ${c.unit}` : '');
  g.fillStyle = '#9ab';
  g.fillText(`${name(cx0, 'x')} ${x0.toFixed(1)} .. ${x1.toFixed(1)}${unit(cx0)}, ` +
    `${name(cy0, 'y')} ${y0.toFixed(1)} .. ${y1.toFixed(1)}${unit(cy0)}`, 8, h - 4);
  rtc.plotted.path = c.length + m.length;
}
// Each process' wake-up latency since it started: log µs across, log samples up.
function plotHist(canvas) {
  const s = surface(canvas, 'wake-up latency, µs');
  rtc.plotted.hist = 0;
  const series = rtc.latency || [];
  const bins = series.flatMap((p) => p.bins);
  if (!s || !bins.length) return;
  const { g, w, h } = s;
  const d0 = Math.floor(Math.log10(Math.max(Math.min(...bins.map((b) => b[0])), 1e-3)));
  const d1 = Math.max(Math.ceil(Math.log10(Math.max(...bins.map((b) => b[1])))), d0 + 1);
  const c1 = Math.max(1, Math.ceil(Math.log10(Math.max(...bins.map((b) => b[2])))));
  const X = (v) => 30 + (Math.log10(Math.max(v, 10 ** d0)) - d0) / (d1 - d0) * (w - 40);
  const Y = (c) => h - 16 - (c > 0 ? (Math.log10(c) + 0.3) / (c1 + 0.3) : 0) * (h - 36);
  g.strokeStyle = '#333';
  g.fillStyle = '#9ab';
  // A label every decade, or every other one where they would touch.
  const every = (w - 40) / (d1 - d0) < 45 ? 2 : 1;
  let right = -Infinity; // where the last label drawn ends: labels never overlap
  for (let d = d0; d <= d1; d++) {
    g.beginPath(); g.moveTo(X(10 ** d), 20); g.lineTo(X(10 ** d), h - 16); g.stroke();
    if ((d - d0) % every === 0) {
      const label = d >= 4 ? `1e${d}` : d >= 0 ? String(10 ** d) : (10 ** d).toFixed(-d);
      const width = g.measureText(label).width;
      // Inside the plot: the last one right-aligned to its edge where it would not fit.
      const x = Math.min(X(10 ** d) - 6, w - 2 - width);
      if (x > right + 4) { g.fillText(label, x, h - 4); right = x + width; }
    }
  }
  series.forEach((p, k) => {
    g.strokeStyle = colors[k % colors.length]; g.lineWidth = 1.5; g.beginPath();
    let end = null;
    for (const [lo, hi, n] of p.bins) {
      if (end === null || Math.abs(lo - end) > 1e-9 * Math.max(lo, 1)) {
        if (end !== null) g.lineTo(X(end), Y(0));
        g.moveTo(X(lo), Y(0));
      }
      g.lineTo(X(lo), Y(n)); g.lineTo(X(hi), Y(n));
      end = hi;
    }
    if (end !== null) g.lineTo(X(end), Y(0));
    g.stroke();
    g.fillStyle = colors[k % colors.length];
    g.textAlign = 'right';
    g.fillText(`${p.name} p99 ${p.p99_us.toFixed(0)}`, w - 4, 14 + 13 * k);
    g.textAlign = 'left';
  });
  g.lineWidth = 1;
  rtc.plotted.hist = series.length;
}
// The commanded and measured tool of a moving program, for the path plot (a new program
// starts a new path; at most 20 000 points each, the oldest dropped).
const PATH_MAX = 20000;
function keepPath(f) {
  const p = f.program;
  if (!p || p.state !== 1 || !f.tool || !f.command_tool) return;
  if (rtc.path.program !== p.id) {
    rtc.path = { program: p.id, commanded: [], measured: [], box: [Infinity, -Infinity, Infinity, -Infinity] };
  }
  const two = (v) => [v[0], v.length > 1 ? v[1] : 0];
  // A point within 1/1000 of the path's extent of the last one kept (a WAIT, a dwell, a
  // slow stretch) adds nothing the plot can show: the page redraws every point each frame.
  const b = rtc.path.box, c = two(f.command_tool);
  rtc.path.box = [Math.min(b[0], c[0]), Math.max(b[1], c[0]), Math.min(b[2], c[1]), Math.max(b[3], c[1])];
  const tol = Math.max(rtc.path.box[1] - rtc.path.box[0], rtc.path.box[3] - rtc.path.box[2]) / 1000;
  const add = (pts, v) => {
    const q = pts[pts.length - 1];
    if (!q || Math.abs(q[0] - v[0]) > tol || Math.abs(q[1] - v[1]) > tol) pts.push(v);
  };
  add(rtc.path.commanded, c);
  add(rtc.path.measured, two(f.tool));
  for (const k of ['commanded', 'measured']) if (rtc.path[k].length > PATH_MAX) rtc.path[k].splice(0, PATH_MAX / 2);
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
  keepPath(f);
  if (f.latency) rtc.latency = f.latency;
  if (rtc.hello) keep(feHist, f.t, f.following_error, rtc.hello.axes.map(a => a.name));
}

// ---- a line's cells (`supervisor web --line`): the list, each a link to its view ----
const text = (v) => String(v ?? '–').replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
function listCells(list) {
  rtc.cells = list;
  $('line').hidden = false;
  $('banner').className = 'ok';
  $('banner').textContent = `the line: ${list.length} cells; choose one`;
  $('cells').innerHTML = '<tr><th>cell</th><th>host</th><th>state</th><th>program</th><th>e-stop</th></tr>' +
    list.map((c) => `<tr><td><a href="/${query(c.cell)}">${text(c.cell)}</a></td><td>${text(c.host)}</td>` +
      `<td>${text(c.state)}</td><td>${text(c.program)}</td><td>${c.estop === null ? '–' : c.estop ? 'latched' : 'clear'}</td></tr>`).join('');
}
if (cellName) {
  $('line').hidden = false;
  $('cells').innerHTML = `<tr><td>${text(cellName)} — <a href="/${query(null)}">every cell of the line</a></td></tr>`;
}

// ---- the connection: again and again, whatever the cell does ----
function connect() {
  const ws = new WebSocket(withToken(`ws://${location.host}/ws`));
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (m.kind === 'hello') { rtc.hello = m; build(m); } else if (m.kind === 'cells') listCells(m.cells); else onFrame(m);
  };
  ws.onclose = () => { rtc.up = false; $('banner').className = 'down'; $('banner').textContent = 'web server unreachable: retrying'; setTimeout(connect, 1000); };
}

async function act(what) {
  $('answer').textContent = `${what}…`;
  try {
    const r = await fetch(withToken(`/api/${what}`), { method: 'POST', headers: { 'X-Rtc-Request': '1' } });
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
  const units = [...new Set((rtc.hello?.axes ?? []).map((a) => a.unit))];
  plotSeries($('fe'), feHist, 'following error', units.length === 1 ? units[0] : '(axis units)');
  plotPath($('path'));
  plotHist($('hist'));
})();
