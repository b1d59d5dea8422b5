// salo's run viewer: WebGL2 points and lines, a 2D error plot. Reads the JSON of tools/view_html.py
// (#salo-data); frames are inflated when first shown. No network, no library.
"use strict";
(() => {
const D = JSON.parse(document.getElementById("salo-data").textContent);
document.getElementById("salo-data").textContent = "";  // parsed: the text (tens of MB) is not kept twice
const $ = (id) => document.getElementById(id);
const errors = [];
function fail(message) {
  errors.push(String(message));
  $("errors").textContent = errors.join("\n");
  document.body.dataset.errors = String(errors.length);
}
window.addEventListener("error", (e) => fail(e.message));
window.addEventListener("unhandledrejection", (e) => fail(e.reason && e.reason.message || e.reason));

// ---------------------------------------------------------------- matrices (column-major, as WebGL takes them)
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
}
function lookAt(eye, at, up) {
  const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
  return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
    -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
}
function mul(a, b) {
  const o = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++)
    for (let k = 0; k < 4; k++) o[c * 4 + r] += a[k * 4 + r] * b[c * 4 + k];
  return o;
}
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
function norm(a) { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; }
// A pose of the data (row-major 4x4, 16 numbers per frame) as a column-major matrix, or null if not finite.
function poseOf(list, k) {
  if (!list) return null;
  const p = list.slice(16 * k, 16 * k + 16);
  if (p.some((v) => v === null)) return null;
  return [p[0], p[4], p[8], 0, p[1], p[5], p[9], 0, p[2], p[6], p[10], 0, p[3], p[7], p[11], 1];
}

// ---------------------------------------------------------------- sources of poses
const sources = [];  // {label, colour, poses, error, weak, kept_bit}
if (D.truth) sources.push({label: "truth", colour: D.truth.colour, poses: D.truth.poses, weak: D.truth.weak});
for (const t of D.tracks) sources.push(t);
if (!sources.length) sources.push({label: "the scan's own frame", colour: "#222", poses: null});

// ---------------------------------------------------------------- frames: inflate on first use
const fields = D.fields;
const cache = new Map();
function bytesOf(b64) {
  const text = atob(b64), out = new Uint8Array(text.length);
  for (let i = 0; i < text.length; i++) out[i] = text.charCodeAt(i);
  return out;
}
async function inflate(b64) {
  const stream = new Blob([bytesOf(b64)]).stream().pipeThrough(new DecompressionStream("deflate"));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}
function frame(k) {
  if (!cache.has(k)) cache.set(k, inflate(D.blobs[k]).then((bytes) => upload(k, bytes)));
  return cache.get(k);
}

// ---------------------------------------------------------------- WebGL2
const canvas = $("view");
const gl = canvas.getContext("webgl2", {antialias: false, preserveDrawingBuffer: false});
if (!gl) { fail("this browser has no WebGL2: the 3D view cannot be drawn"); }
const POINT_VS = `#version 300 es
in vec3 a_pos; in float a_ring; in float a_int; in float a_class; in float a_moving; in float a_kept;
uniform mat4 u_view; uniform mat4 u_pose; uniform float u_q; uniform float u_size; uniform int u_mode;
uniform float u_rings; uniform float u_keptBit; uniform vec2 u_z; uniform float u_fade;
uniform vec3 u_classes[32];
out vec3 v_col;
vec3 ramp(float t) {  // a perceptual-ish ramp: navy, blue, teal, green, yellow, red
  t = clamp(t, 0.0, 1.0) * 5.0;
  vec3 c[6] = vec3[6](vec3(.15,.1,.45), vec3(.1,.35,.85), vec3(.1,.7,.75), vec3(.35,.8,.3), vec3(.95,.8,.15),
                      vec3(.85,.15,.1));
  int i = int(min(floor(t), 4.0));
  return mix(c[i], c[i + 1], t - float(i));
}
void main() {
  vec4 w = u_pose * vec4(a_pos * u_q, 1.0);
  gl_Position = u_view * w;
  gl_PointSize = u_size;
  vec3 col;
  if (u_mode == 0) col = ramp(a_ring / max(u_rings - 1.0, 1.0));
  else if (u_mode == 1) col = ramp(sqrt(a_int / 255.0));
  else if (u_mode == 2) col = ramp((w.z - u_z.x) / (u_z.y - u_z.x));
  else if (u_mode == 3) col = u_classes[int(a_class) % 32];
  else if (u_mode == 4) col = a_moving > 0.5 ? vec3(.85,.15,.1) : vec3(.6,.6,.6);
  else col = mod(floor(a_kept / exp2(u_keptBit)), 2.0) > 0.5 ? vec3(.1,.55,.2) : vec3(.85,.2,.15);
  v_col = mix(col, vec3(.78), u_fade);
}`;
const POINT_FS = `#version 300 es
precision mediump float; in vec3 v_col; out vec4 o;
void main() { o = vec4(v_col, 1.0); }`;
const LINE_VS = `#version 300 es
in vec3 a_pos; uniform mat4 u_view; uniform float u_size;
void main() { gl_Position = u_view * vec4(a_pos, 1.0); gl_PointSize = u_size; }`;
const LINE_FS = `#version 300 es
precision mediump float; uniform vec3 u_col; out vec4 o;
void main() { o = vec4(u_col, 1.0); }`;
function program(vs, fs) {
  const p = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(s));
    gl.attachShader(p, s);
  }
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error("program: " + gl.getProgramInfoLog(p));
  const u = {}, a = {};
  for (let i = 0; i < gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS); i++) {
    const name = gl.getActiveUniform(p, i).name.replace("[0]", "");
    u[name] = gl.getUniformLocation(p, name);
  }
  for (let i = 0; i < gl.getProgramParameter(p, gl.ACTIVE_ATTRIBUTES); i++) {
    const name = gl.getActiveAttrib(p, i).name;
    a[name] = gl.getAttribLocation(p, name);
  }
  return {p, u, a};
}
const points = gl && program(POINT_VS, POINT_FS);
const lines = gl && program(LINE_VS, LINE_FS);
const hex = (c) => [1, 3, 5].map((i) => parseInt(c.slice(i, i + 2), 16) / 255);

// One scan's vertex array: positions (int16 differences summed), then the uint8 fields present.
function upload(k, bytes) {
  const n = D.counts[k], view = new DataView(bytes.buffer);
  const pos = new Int16Array(3 * n);
  let off = 0;
  for (let axis = 0; axis < 3; axis++) {
    let v = 0;
    for (let i = 0; i < n; i++, off += 2) { v = (v + view.getInt16(off, true)) << 16 >> 16; pos[3 * i + axis] = v; }
  }
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const buffer = (data, loc, size, type) => {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, size, type, false, 0, 0);
  };
  buffer(pos, points.a.a_pos, 3, gl.SHORT);
  for (const [name, present] of [["a_ring", fields.ring], ["a_int", fields.intensity], ["a_class", fields.class],
    ["a_moving", fields.moving], ["a_kept", fields.kept]]) {
    const loc = points.a[name];
    if (loc === undefined || loc < 0) { if (present) off += n; continue; }
    if (present) { buffer(bytes.subarray(off, off + n), loc, 1, gl.UNSIGNED_BYTE); off += n; }
    else { gl.disableVertexAttribArray(loc); gl.vertexAttrib1f(loc, 0); }
  }
  gl.bindVertexArray(null);
  let zmin = Infinity, zmax = -Infinity;
  for (let i = 2; i < pos.length; i += 3) { if (pos[i] < zmin) zmin = pos[i]; if (pos[i] > zmax) zmax = pos[i]; }
  return {vao, n, zmin: zmin * D.quantum, zmax: zmax * D.quantum};
}

// Trajectories: one line strip per source, in the first scan's frame.
const strips = sources.filter((s) => s.poses).map((s) => {
  const xyz = [];
  for (let k = 0; k < D.frames; k++) {
    const p = poseOf(s.poses, k);
    if (p) xyz.push(p[12], p[13], p[14] + 0.05);
  }
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const b = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, b);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(xyz), gl.STATIC_DRAW);
  gl.enableVertexAttribArray(lines.a.a_pos);
  gl.vertexAttribPointer(lines.a.a_pos, 3, gl.FLOAT, false, 0, 0);
  gl.bindVertexArray(null);
  return {source: s, vao, count: xyz.length / 3};
});

// ---------------------------------------------------------------- controls
const colourModes = [];
if (fields.ring) colourModes.push(["ring", 0]);
if (fields.intensity) colourModes.push(["intensity", 1]);
colourModes.push(["height", 2]);
if (fields.class) colourModes.push(["object class (truth)", 3]);
if (fields.moving) colourModes.push(["moving / static (truth)", 4]);
for (const t of D.tracks) if (t.kept_bit >= 0) colourModes.push([`kept / dropped by ${t.label}'s filters`, 5, t.kept_bit]);
for (const [i, m] of colourModes.entries()) $("colour").add(new Option(m[0], i));
for (const [i, s] of sources.entries()) { $("place").add(new Option(s.label, i)); $("place2").add(new Option(s.label, i)); }
if (sources.length > 1) $("place2").value = "1";
$("frame").max = D.frames - 1;
$("notes").textContent = D.notes.join("; ");

const camera = {yaw: -2.3, pitch: 0.55, distance: 60, target: [0, 0, 0]};
let current = 0, playing = null;

function legend() {
  const mode = colourModes[+$("colour").value];
  const parts = sources.filter((s) => s.poses).map((s) =>
    `<span><i class="swatch" style="background:${s.colour}"></i>${s.label} trajectory</span>`);
  if (mode[1] === 3) D.classes.forEach((c, i) =>
    parts.push(`<span><i class="swatch" style="background:${D.class_colours[i]}"></i>${c}</span>`));
  if (mode[1] === 5) parts.push('<span><i class="swatch" style="background:#1a8c33"></i>kept</span>',
    '<span><i class="swatch" style="background:#d93326"></i>dropped</span>');
  if (mode[1] === 0 || mode[1] === 1 || mode[1] === 2) parts.push(`<span>${mode[0]}: low ` +
    '<i class="swatch" style="background:linear-gradient(90deg,#261a73,#1a59d9,#1ab3bf,#59cc4d,#f2cc26,#d9261a);' +
    'width:60px"></i> high</span>');
  $("legend").innerHTML = parts.join("");
}

function resize() {
  const r = canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
  canvas.width = Math.max(1, Math.round(r.width * dpr));
  canvas.height = Math.max(1, Math.round(r.height * dpr));
  const p = $("plot"), q = p.getBoundingClientRect();
  p.width = Math.round(q.width * dpr); p.height = Math.round(q.height * dpr);
}

async function draw() {
  const k = current, trail = Math.max(0, Math.min(50, +$("trail").value || 0));
  const wanted = [];
  for (let j = Math.max(0, k - trail); j <= k; j++) wanted.push(j);
  const scans = await Promise.all(wanted.map(frame));
  if (k !== current) return;  // a newer frame was asked for meanwhile
  const split = $("split").checked && sources.length > 1;
  const places = split ? [+$("place").value, +$("place2").value] : [+$("place").value];
  const anchor = poseOf(sources[places[0]].poses, k);
  if ($("follow").checked && anchor) camera.target = [anchor[12], anchor[13], anchor[14]];
  gl.enable(gl.DEPTH_TEST);
  gl.enable(gl.SCISSOR_TEST);
  gl.clearColor(1, 1, 1, 1);
  const width = canvas.width / places.length;
  places.forEach((place, side) => {
    gl.viewport(side * width, 0, width, canvas.height);
    gl.scissor(side * width, 0, width, canvas.height);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    const eye = [camera.target[0] + camera.distance * Math.cos(camera.pitch) * Math.cos(camera.yaw),
      camera.target[1] + camera.distance * Math.cos(camera.pitch) * Math.sin(camera.yaw),
      camera.target[2] + camera.distance * Math.sin(camera.pitch)];
    const up = Math.abs(camera.pitch) > 1.55 ? [Math.cos(camera.yaw + Math.PI), Math.sin(camera.yaw + Math.PI), 0]
      : [0, 0, 1];
    const viewMatrix = mul(perspective(0.9, width / canvas.height, 0.2, 4000), lookAt(eye, camera.target, up));
    const mode = colourModes[+$("colour").value];
    gl.useProgram(points.p);
    gl.uniformMatrix4fv(points.u.u_view, false, viewMatrix);
    gl.uniform1f(points.u.u_q, D.quantum);
    gl.uniform1f(points.u.u_size, +$("size").value * (window.devicePixelRatio || 1));
    gl.uniform1i(points.u.u_mode, mode[1]);
    gl.uniform1f(points.u.u_rings, D.rings || 64);
    gl.uniform1f(points.u.u_keptBit, mode[2] || 0);
    const colours = new Float32Array(96);
    D.class_colours.slice(0, 32).forEach((c, i) => colours.set(hex(c), 3 * i));
    if (points.u.u_classes) gl.uniform3fv(points.u.u_classes, colours);
    const own = scans[scans.length - 1];
    const base = anchor ? anchor[14] : 0;
    gl.uniform2f(points.u.u_z, base + own.zmin, base + Math.max(own.zmax, own.zmin + 1));
    scans.forEach((scan, i) => {
      const pose = poseOf(sources[place].poses, wanted[i]) || (sources[place].poses ? null
        : [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
      if (!pose) return;  // the method diverged before this frame: no pose to place the scan by
      gl.uniformMatrix4fv(points.u.u_pose, false, pose);
      gl.uniform1f(points.u.u_fade, i === scans.length - 1 ? 0 : 0.55);
      gl.bindVertexArray(scan.vao);
      gl.drawArrays(gl.POINTS, 0, scan.n);
    });
    gl.useProgram(lines.p);
    gl.uniformMatrix4fv(lines.u.u_view, false, viewMatrix);
    gl.lineWidth(1);
    for (const s of strips) {
      gl.uniform3fv(lines.u.u_col, hex(s.source.colour));
      gl.bindVertexArray(s.vao);
      gl.drawArrays(gl.LINE_STRIP, 0, s.count);
      const p = poseOf(s.source.poses, k);
      if (p) {  // the frame's position on each trajectory
        const marker = gl.createBuffer();
        gl.bindVertexArray(null);
        gl.bindBuffer(gl.ARRAY_BUFFER, marker);
        gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([p[12], p[13], p[14] + 0.05]), gl.STREAM_DRAW);
        gl.enableVertexAttribArray(lines.a.a_pos);
        gl.vertexAttribPointer(lines.a.a_pos, 3, gl.FLOAT, false, 0, 0);
        gl.uniform1f(lines.u.u_size, 9 * (window.devicePixelRatio || 1));
        gl.drawArrays(gl.POINTS, 0, 1);
        gl.deleteBuffer(marker);
      }
    }
    gl.bindVertexArray(null);
    const caption = $(side ? "cap-right" : "cap-left");
    caption.textContent = `scans placed by ${sources[place].label}`;
    caption.style.left = `${(side * 100) / places.length + 0.5}%`;
  });
  $("cap-right").style.display = split ? "" : "none";
  $("frame-label").textContent = `${D.frame_numbers[k]} (${k + 1} of ${D.frames})`;
  const words = [`frame ${D.frame_numbers[k]}`, `t = ${(D.times[k] ?? 0).toFixed(2)} s`,
    `${D.distance[k].toFixed(1)} m along the path`, `${scans[scans.length - 1].n} points`];
  for (const t of D.tracks) if (t.error) words.push(`${t.label}: error ${t.error[k] === null ? "n/a (diverged)"
    : t.error[k].toFixed(3) + " m"}${t.weak && t.weak[k] ? " (flagged weak)" : ""}`);
  if (D.truth && D.truth.weak && D.truth.weak[k]) words.push("weakly constrained in the truth");
  $("readout").textContent = words.join(" \u00b7 ");
  plot();
  if (document.body.dataset.status === "loading") document.body.dataset.firstDrawMs = String(Math.round(performance.now()));
  if (document.body.dataset.status !== "walked") document.body.dataset.status = "drawn";
  document.body.dataset.frame = String(k);
  document.body.dataset.points = String(scans[scans.length - 1].n);
}

// The error of each method per frame (m) against the distance travelled; the truth's weak frames shaded.
function plot() {
  const c = $("plot"), g = c.getContext("2d"), w = c.width, h = c.height, dpr = window.devicePixelRatio || 1;
  g.clearRect(0, 0, w, h);
  const left = 52 * dpr, right = 10 * dpr, top = 8 * dpr, bottom = 22 * dpr;
  const dmax = Math.max(D.distance[D.frames - 1], 1e-6);
  const x = (d) => left + (w - left - right) * d / dmax;
  const tracks = D.tracks.filter((t) => t.error);
  const emax = Math.max(1e-3, ...tracks.flatMap((t) => t.error.filter((e) => e !== null)));
  const y = (e) => h - bottom - (h - top - bottom) * e / emax;
  g.font = `${11 * dpr}px system-ui, sans-serif`;
  g.fillStyle = "#555";
  if (D.truth && D.truth.weak) {
    g.fillStyle = "rgba(244,199,161,0.7)";
    D.truth.weak.forEach((weak, k) => { if (weak) g.fillRect(x(D.distance[Math.max(k - 0.5, 0) | 0]), top,
      Math.max(2, x(D.distance[Math.min(k + 1, D.frames - 1)]) - x(D.distance[k])), h - top - bottom); });
  }
  g.strokeStyle = "#bbb"; g.lineWidth = 1;
  g.strokeRect(left, top, w - left - right, h - top - bottom);
  g.fillStyle = "#555";
  g.fillText(`${emax.toPrecision(2)} m`, 4 * dpr, top + 10 * dpr);
  g.fillText("0", left - 12 * dpr, h - bottom);
  g.fillText(`distance along the path, m (0 to ${dmax.toFixed(0)}); position error of each method`,
    left, h - 6 * dpr);
  if (!tracks.length) g.fillText("no method's error to show (no run, or no truth)", left + 8 * dpr, top + 20 * dpr);
  for (const t of tracks) {
    g.strokeStyle = t.colour; g.lineWidth = 1.5 * dpr; g.beginPath();
    let pen = false;
    t.error.forEach((e, k) => {
      if (e === null) { pen = false; return; }
      if (pen) g.lineTo(x(D.distance[k]), y(e)); else g.moveTo(x(D.distance[k]), y(e));
      pen = true;
    });
    g.stroke();
  }
  g.strokeStyle = "#000"; g.lineWidth = dpr; g.beginPath();
  g.moveTo(x(D.distance[current]), top); g.lineTo(x(D.distance[current]), h - bottom); g.stroke();
}

function show(k) {
  current = Math.max(0, Math.min(D.frames - 1, k));
  $("frame").value = current;
  draw().catch(fail);
  for (let j = current + 1; j <= Math.min(D.frames - 1, current + 3); j++) frame(j);  // inflate ahead
}
function togglePlay() {
  if (playing) { clearInterval(playing); playing = null; $("play").innerHTML = "&#9654;"; return; }
  $("play").innerHTML = "&#10074;&#10074;";
  playing = setInterval(() => show(current + 1 < D.frames ? current + 1 : 0), 100);
}
$("frame").addEventListener("input", () => show(+$("frame").value));
$("play").addEventListener("click", togglePlay);
for (const id of ["place", "place2", "split", "trail", "size", "follow"]) $(id).addEventListener("input", () => show(current));
$("colour").addEventListener("input", () => { legend(); show(current); });
$("top").addEventListener("click", () => { camera.pitch = 1.5707; camera.distance = 120; show(current); });
window.addEventListener("keydown", (e) => {
  if (e.target.tagName === "INPUT" && e.target.type !== "range") return;
  if (e.key === " ") { e.preventDefault(); togglePlay(); }
  if (e.key === "ArrowRight") show(current + 1);
  if (e.key === "ArrowLeft") show(current - 1);
});
let drag = null;
canvas.addEventListener("pointerdown", (e) => { drag = {x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2};
  canvas.setPointerCapture(e.pointerId); });
canvas.addEventListener("pointerup", () => { drag = null; });
canvas.addEventListener("contextmenu", (e) => e.preventDefault());
canvas.addEventListener("pointermove", (e) => {
  if (!drag) return;
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  drag.x = e.clientX; drag.y = e.clientY;
  if (drag.pan) {  // move the target in the ground plane, as the mouse moves on screen
    const s = camera.distance / 600;
    $("follow").checked = false;
    camera.target[0] += s * (dx * Math.sin(camera.yaw) + dy * Math.cos(camera.yaw));
    camera.target[1] += s * (-dx * Math.cos(camera.yaw) + dy * Math.sin(camera.yaw));
  } else {
    camera.yaw -= dx * 0.006;
    camera.pitch = Math.max(-1.55, Math.min(1.5707, camera.pitch + dy * 0.006));
  }
  draw().catch(fail);
});
canvas.addEventListener("wheel", (e) => { e.preventDefault();
  camera.distance = Math.max(2, Math.min(3000, camera.distance * Math.exp(e.deltaY * 0.001))); draw().catch(fail); },
{passive: false});
$("plot").addEventListener("click", (e) => {
  const r = $("plot").getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
  const d = (e.clientX - r.left - 52) / (r.width - 62) * D.distance[D.frames - 1];
  let best = 0;
  D.distance.forEach((v, k) => { if (Math.abs(v - d) < Math.abs(D.distance[best] - d)) best = k; });
  show(best);
  void dpr;
});
window.addEventListener("resize", () => { resize(); show(current); });

if (gl) {
  // A camera distance that takes in the first scan's extent, at most 80 m.
  frame(0).then((s) => { camera.distance = Math.min(80, Math.max(15, 0.6 * (s.zmax - s.zmin) + 30)); });
  // Side by side from the start when there is something to compare: two methods, or the truth and one.
  if (D.tracks.length >= 2) { $("place").value = String(sources.length - D.tracks.length);
    $("place2").value = String(sources.length - D.tracks.length + 1); $("split").checked = true; }
  else if (D.tracks.length === 1 && D.truth) $("split").checked = true;
  // The address may choose the start: page.html#frame=40&colour=intensity&trail=0&split=0&top=1
  const wish = new URLSearchParams(location.hash.slice(1));
  const modeNamed = (name) => colourModes.findIndex((m) => m[0].startsWith(name));
  if (wish.has("colour") && modeNamed(wish.get("colour")) >= 0) $("colour").value = String(modeNamed(wish.get("colour")));
  if (wish.has("trail")) $("trail").value = wish.get("trail");
  if (wish.has("split")) $("split").checked = wish.get("split") !== "0";
  if (wish.has("top")) { camera.pitch = 1.5707; }
  resize();
  legend();
  show(wish.has("frame") ? Math.round(+wish.get("frame")) || 0 : 0);
  if (wish.has("walk")) walk();  // #walk: draw every frame once, in order (tools/bench_view.py times it)
}

async function walk() {
  const t0 = performance.now();
  for (let k = 0; k < D.frames; k++) { current = k; $("frame").value = k; await draw(); }
  document.body.dataset.walkMs = String(Math.round(performance.now() - t0));
  document.body.dataset.status = "walked";
}
})();
