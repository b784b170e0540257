// The control panel's page: the report's buttons and slider, the teleop keys, and what the
// control_panel node streams back (odometry, camera, the pipeline's state). Dead man: a held
// button or key is repeated to the node every HEARTBEAT_MS; the node stops the robot when the
// repetition stops (release, a closed or hidden page, a lost connection).
'use strict';

const HEARTBEAT_MS = 100;
const KEYS = {
  i: 'forward', w: 'forward', ',': 'backward', x: 'backward',
  j: 'left', a: 'left', l: 'right', d: 'right',
  J: 'strafe_left', q: 'strafe_left', L: 'strafe_right', e: 'strafe_right',
};
const STOP_KEYS = new Set(['k', 's', ' ']);
const COLOURS = { orange: '#f97316', purple: '#9333ea', blue: '#2563eb' };

const $ = (id) => document.getElementById(id);
let socket = null;
let held = null;            // the motion held by a button or key
let heartbeat = null;
let robots = [];
let current = null;         // the robot driven
let path = [];

function send(message) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
}

function hold(motion) {
  if (held === motion) return;
  held = motion;
  document.querySelectorAll('.pad button').forEach(
    (b) => b.classList.toggle('active', b.dataset.motion === motion));
  send({ op: 'hold', motion });
  clearInterval(heartbeat);
  heartbeat = setInterval(() => send({ op: 'hold', motion }), HEARTBEAT_MS);
}

function release(op = 'release') {
  clearInterval(heartbeat);
  heartbeat = null;
  if (held !== null || op === 'stop') send({ op });
  held = null;
  document.querySelectorAll('.pad button').forEach((b) => b.classList.remove('active'));
}

function setSpeed(fraction, tell = true) {
  const value = Math.min(1, Math.max(0, Math.round(fraction * 20) / 20));
  $('speed').value = value;
  $('speed_value').textContent = `${Math.round(value * 100)} %`;
  if (tell) send({ op: 'speed', fraction: value });
}

function showRobot(namespace) {
  current = robots.find((r) => r.namespace === namespace) || null;
  $('robot').value = namespace;
  const holonomic = !!(current && current.holonomic);
  // (kept in the pad's grid when hidden, so the other buttons stay where they are)
  document.querySelectorAll('.strafe').forEach((b) => {
    b.style.visibility = holonomic ? 'visible' : 'hidden';
  });
  $('strafe_keys').hidden = !holonomic;
  $('report_turns_option').hidden = !(current && current.report_turns);
  $('camera_topic').textContent = current && current.camera ? current.camera : 'no camera';
  $('camera').style.visibility = current && current.camera ? 'visible' : 'hidden';
  $('camera').removeAttribute('src');
}

function onHello(msg) {
  robots = msg.robots;
  const select = $('robot');
  select.replaceChildren(...robots.map((r) => {
    const option = document.createElement('option');
    option.value = r.namespace;
    option.textContent = `${r.name} (${r.namespace}${r.holonomic ? ', holonomic' : ''})`;
    return option;
  }));
  if (msg.namespace !== (current && current.namespace)) path = [];
  showRobot(msg.namespace);
  setSpeed(msg.speed, false);
  $('report_turns').checked = msg.report_turns;
  showError(msg.error);
}

function showError(text) {
  $('error').hidden = !text;
  $('error').textContent = text || '';
}

function fmt(value, digits = 3) {
  return value === undefined || value === null ? '–' : Number(value).toFixed(digits);
}

function onState(msg) {
  const o = msg.odom;
  if (o) {
    $('odom_x').textContent = fmt(o.x);
    $('odom_y').textContent = fmt(o.y);
    $('odom_yaw').textContent = fmt(o.yaw);
    $('odom_v').textContent = fmt(Math.hypot(o.vx, o.vy));
    $('odom_w').textContent = fmt(o.wz);
    $('odom_t').textContent = fmt(o.t, 2);
  }
  const [vx, vy, wz] = msg.command;
  $('command').textContent = msg.motion === 'stop' ? 'stop'
    : `${msg.motion}: vx ${fmt(vx)} vy ${fmt(vy)} wz ${fmt(wz)}`;
  path = msg.path;
  drawPath(o);
  showCell(msg.coordinator, msg.materials);
}

function drawPath(odom) {
  const canvas = $('path');
  const g = canvas.getContext('2d');
  g.fillStyle = '#111827';
  g.fillRect(0, 0, canvas.width, canvas.height);
  const points = path.length ? path : (odom ? [[odom.x, odom.y]] : []);
  if (!points.length) return;
  const xs = points.map((p) => p[0]);
  const ys = points.map((p) => p[1]);
  const cx = (Math.min(...xs) + Math.max(...xs)) / 2;
  const cy = (Math.min(...ys) + Math.max(...ys)) / 2;
  const span = Math.max(0.5, Math.max(...xs) - Math.min(...xs), Math.max(...ys) - Math.min(...ys));
  const scale = 0.8 * Math.min(canvas.width, canvas.height) / span;
  const px = (x) => canvas.width / 2 + (x - cx) * scale;
  const py = (y) => canvas.height / 2 - (y - cy) * scale;
  g.strokeStyle = '#374151';
  g.lineWidth = 1;
  const grid = span > 3 ? 1 : 0.1 * Math.ceil(span / 1.5);
  for (let x = Math.floor((cx - span) / grid) * grid; x < cx + span; x += grid) {
    g.beginPath(); g.moveTo(px(x), 0); g.lineTo(px(x), canvas.height); g.stroke();
  }
  for (let y = Math.floor((cy - span) / grid) * grid; y < cy + span; y += grid) {
    g.beginPath(); g.moveTo(0, py(y)); g.lineTo(canvas.width, py(y)); g.stroke();
  }
  g.strokeStyle = '#38bdf8';
  g.lineWidth = 2;
  g.beginPath();
  points.forEach(([x, y], k) => (k ? g.lineTo(px(x), py(y)) : g.moveTo(px(x), py(y))));
  g.stroke();
  if (odom) {                 // the robot: a triangle along its heading
    const [x, y, a] = [px(odom.x), py(odom.y), -odom.yaw];
    g.fillStyle = '#facc15';
    g.beginPath();
    g.moveTo(x + 10 * Math.cos(a), y + 10 * Math.sin(a));
    g.lineTo(x + 6 * Math.cos(a + 2.5), y + 6 * Math.sin(a + 2.5));
    g.lineTo(x + 6 * Math.cos(a - 2.5), y + 6 * Math.sin(a - 2.5));
    g.fill();
  }
  g.fillStyle = '#9ca3af';
  g.fillText(`grid ${grid.toFixed(1)} m`, 6, canvas.height - 6);
}

let shownMaterials = null;
function showCell(state, materials) {
  $('cell').hidden = !state;
  if (!state) return;
  $('cell_status').textContent = `(${state.status})`;
  $('cell_elapsed').textContent = fmt(state.elapsed, 1);
  $('cell_loader').textContent = state.loader;
  $('cell_transport').textContent = state.transport;
  $('cell_counts').textContent = `${state.total} materials: ${state.identified} identified, `
    + `${state.picked} picked, ${state.delivered} delivered, ${state.missed} missed, `
    + `${state.failed} failed`;
  // The table is rebuilt only when a material changed (10 state messages a second).
  const key = JSON.stringify(materials);
  if (key === shownMaterials) return;
  shownMaterials = key;
  $('materials').tBodies[0].replaceChildren(...materials.map((m) => {
    const row = document.createElement('tr');
    const swatch = `<span class="swatch" style="background:${COLOURS[m.color] || '#999'}"></span>`;
    row.innerHTML = `<td>${m.id}</td><td>${swatch}</td><td></td><td></td><td></td><td></td>`;
    [m.color, m.status, m.robot, m.detail, fmt(m.t, 1)].forEach((text, k) => {
      if (k === 0) row.cells[1].append(text); else row.cells[k + 1].textContent = text;
    });
    return row;
  }));
}

let frameUrl = null;
function onFrame(blob) {
  const url = URL.createObjectURL(new Blob([blob], { type: 'image/jpeg' }));
  $('camera').src = url;
  if (frameUrl) URL.revokeObjectURL(frameUrl);
  frameUrl = url;
}

function connect() {
  const status = $('status');
  socket = new WebSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`);
  socket.binaryType = 'arraybuffer';
  socket.onopen = () => { status.textContent = 'connected'; status.className = 'status online'; };
  socket.onclose = () => {
    status.textContent = 'disconnected: reconnecting…';
    status.className = 'status offline';
    release();
    setTimeout(connect, 1000);
  };
  socket.onmessage = (event) => {
    if (typeof event.data !== 'string') { onFrame(event.data); return; }
    const msg = JSON.parse(event.data);
    if (msg.op === 'hello') onHello(msg);
    else if (msg.op === 'state') onState(msg);
    else if (msg.op === 'error') showError(msg.text);
    else if (msg.op === 'refused') console.warn('refused:', msg.text);
  };
}

document.querySelectorAll('.pad button[data-motion]').forEach((button) => {
  button.addEventListener('pointerdown', (e) => {
    button.setPointerCapture(e.pointerId);
    hold(button.dataset.motion);
  });
  for (const ends of ['pointerup', 'pointercancel', 'lostpointercapture']) {
    button.addEventListener(ends, () => release());
  }
});
$('stop').addEventListener('click', () => release('stop'));
$('speed').addEventListener('input', (e) => setSpeed(parseFloat(e.target.value)));
$('report_turns').addEventListener('change',
  (e) => send({ op: 'report_turns', on: e.target.checked }));
$('robot').addEventListener('change', (e) => {
  release('stop');
  send({ op: 'select', namespace: e.target.value });
});
document.addEventListener('keydown', (e) => {
  if (e.target.tagName === 'SELECT' || e.ctrlKey || e.metaKey || e.altKey) return;
  const motion = KEYS[e.key];
  if (motion && (!motion.startsWith('strafe') || (current && current.holonomic))) {
    e.preventDefault();
    hold(motion);
  } else if (STOP_KEYS.has(e.key)) {
    e.preventDefault();
    release('stop');
  } else if (e.key === '+' || e.key === '=') {
    setSpeed(parseFloat($('speed').value) + 0.1);
  } else if (e.key === '-' || e.key === '_') {
    setSpeed(parseFloat($('speed').value) - 0.1);
  }
});
document.addEventListener('keyup', (e) => { if (KEYS[e.key] === held) release(); });
// A page that is hidden or left drives nothing.
document.addEventListener('visibilitychange', () => { if (document.hidden) release(); });
window.addEventListener('blur', () => release());
window.addEventListener('pagehide', () => release());
connect();
