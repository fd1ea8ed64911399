// The run viewer: draws the world the simulator describes and moves its links frame by frame.
// three.js comes from this server (installed from the npm registry by deploy/install.sh).
import * as THREE from "three";
import { OrbitControls } from "three/addons/OrbitControls.js";

const box = document.getElementById("viewer");
const canvas = document.getElementById("viewer-canvas");
const mode = box.dataset.mode;
const CHUNK_S = 10;
const api = { ready: false, t: 0, step: null, bodies: 0, error: null };
window.cloudsimViewer = api;

const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xbfd9f2);
const camera = new THREE.PerspectiveCamera(50, 16 / 9, 0.05, 500);
camera.up.set(0, 0, 1); // the simulator's world is z-up; keep its coordinates as they are
camera.position.set(-4, -5, 3);
const controls = new OrbitControls(camera, canvas);
controls.target.set(0, 0, 0.9);
scene.add(new THREE.HemisphereLight(0xffffff, 0x556655, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.4);
sun.position.set(-10, -6, 20);
scene.add(sun);

const linkGroups = new Map(); // body id -> [THREE.Group per link, base first]
let robotId = null;

function setPose(group, p, at) {
  group.position.set(p[at], p[at + 1], p[at + 2]);
  group.quaternion.set(p[at + 3], p[at + 4], p[at + 5], p[at + 6]);
}

function geometryOf(shape) {
  let geometry;
  switch (shape.type) {
    case "box": return new THREE.BoxGeometry(...shape.size);
    case "sphere": return new THREE.SphereGeometry(shape.radius, 16, 12);
    case "cylinder": geometry = new THREE.CylinderGeometry(shape.radius, shape.radius, shape.length, 20); break;
    case "capsule": geometry = new THREE.CapsuleGeometry(shape.radius, shape.length, 4, 12); break;
    case "plane": return new THREE.PlaneGeometry(400, 400);
    default: return new THREE.BoxGeometry(0.1, 0.1, 0.1); // meshes: a marker where they are
  }
  geometry.rotateX(Math.PI / 2); // three.js builds these along y; the simulator along z
  return geometry;
}

function label(text, position) {
  const paper = document.createElement("canvas");
  paper.width = 256; paper.height = 64;
  const pen = paper.getContext("2d");
  pen.fillStyle = "rgba(255,255,255,0.85)"; pen.fillRect(0, 0, 256, 64);
  pen.fillStyle = "#222"; pen.font = "bold 34px sans-serif"; pen.textAlign = "center";
  pen.fillText(text, 128, 44);
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: new THREE.CanvasTexture(paper) }));
  sprite.position.set(...position);
  sprite.scale.set(1.6, 0.4, 1);
  scene.add(sprite);
}

function buildScene(description) {
  robotId = description.roles.robot;
  for (const body of description.bodies) {
    const groups = body.links.map((name) => {
      const group = new THREE.Group();
      group.name = `${body.name}/${name}`;
      scene.add(group);
      return group;
    });
    for (const shape of body.shapes) {
      const [r, g, b, a] = shape.rgba;
      const material = new THREE.MeshLambertMaterial({
        color: new THREE.Color(r, g, b), transparent: a < 1, opacity: a,
      });
      if (shape.type === "plane") material.color.set(0x9aa58f);
      const mesh = new THREE.Mesh(geometryOf(shape), material);
      mesh.position.set(...shape.xyz);
      mesh.quaternion.set(...shape.quat);
      groups[shape.link].add(mesh);
    }
    if (body.poses) groups.forEach((group, i) => setPose(group, body.poses, 7 * i));
    linkGroups.set(String(body.id), groups);
  }
  for (const [name, gate] of Object.entries(description.roles.gates || {})) {
    label(name.replace("_", " "), [gate.x, gate.y, 3.0]);
  }
  api.bodies = description.bodies.length;
}

function showFrame(frame) {
  for (const [id, poses] of Object.entries(frame.poses)) {
    const groups = linkGroups.get(id);
    if (groups) groups.forEach((group, i) => setPose(group, poses, 7 * i));
  }
  api.t = frame.t;
  api.step = frame.step;
  document.getElementById("viewer-time").textContent = frame.t.toFixed(2);
  if (mode === "replay") { // the score and falls as they stood at this moment
    const past = replayMarks.filter((mark) => mark.t <= frame.t + 1e-9);
    document.getElementById("viewer-score").textContent = past.reduce((sum, m) => sum + m.points, 0);
    document.getElementById("viewer-falls").textContent = past.filter((m) => m.kind === "fall").length;
  }
  markBandwidth(frame.t);
}

// For tests and curious people: where a link is drawn, in world coordinates.
api.linkPosition = (bodyId, link) => {
  const group = linkGroups.get(String(bodyId))[link];
  group.updateWorldMatrix(true, false);
  return new THREE.Vector3().setFromMatrixPosition(group.matrixWorld).toArray();
};
api.robotId = () => robotId;

let lastFollow = null;
function follow() {
  if (!document.getElementById("viewer-follow").checked || robotId === null) { lastFollow = null; return; }
  const at = new THREE.Vector3(...api.linkPosition(robotId, 0));
  if (lastFollow) camera.position.add(at.clone().sub(lastFollow)); // keep the chosen angle
  controls.target.copy(at);
  lastFollow = at;
}

function resize() {
  const width = canvas.clientWidth, height = canvas.clientHeight;
  if (canvas.width !== width || canvas.height !== height) {
    renderer.setSize(width, height, false);
    camera.aspect = width / height;
    camera.updateProjectionMatrix();
  }
}

function status(text) { document.getElementById("viewer-status").textContent = text; }

async function getJSON(url) {
  const response = await fetch(url, { credentials: "same-origin" });
  if (!response.ok) throw new Error(`${response.status} ${response.statusText}`);
  return response.json();
}

// -- the timeline: score events as marks, the bandwidth charts' marker ---------------------
const scrub = document.getElementById("viewer-scrub");
function drawMarks(marks, duration) {
  const holder = document.getElementById("viewer-marks");
  holder.replaceChildren();
  for (const mark of marks) {
    const button = document.createElement("button");
    button.type = "button";
    button.className = `viewer-mark ${mark.kind}`;
    button.style.left = `${(100 * mark.t) / Math.max(duration, 1e-6)}%`;
    button.title = `${mark.t.toFixed(2)} s: ${mark.label}`;
    button.textContent = mark.kind === "checkpoint" ? "★" : mark.kind === "fall" ? "✕" : "•";
    button.dataset.t = mark.t;
    button.addEventListener("click", () => seek(mark.t));
    holder.append(button);
  }
}

const replayChannel = window.cloudsimReplayMark.channel(box.dataset.runId);
const bandwidthCharts = document.getElementById("viewer-bandwidth");
let markedSecond = null;
function markBandwidth(t) {
  if (bandwidthCharts) window.cloudsimReplayMark.markCharts(bandwidthCharts, t);
  if (replayChannel && mode === "replay" && Math.floor(t) !== markedSecond) {
    markedSecond = Math.floor(t);
    replayChannel.postMessage({ t }); // the run's page marks the same second on its charts
  }
}

// -- replay -------------------------------------------------------------------------------
const chunks = new Map(); // chunk index -> Promise of frames
let replayMarks = [];
let playing = false, speed = 1, simTime = 0, duration = 0;

function chunk(index) {
  if (!chunks.has(index)) {
    const url = `${box.dataset.framesUrl}?start=${index * CHUNK_S}&seconds=${CHUNK_S}`;
    chunks.set(index, getJSON(url).then((body) => body.frames).catch((error) => {
      chunks.delete(index);
      throw error;
    }));
  }
  return chunks.get(index);
}

async function showTime(t) {
  const index = Math.floor(t / CHUNK_S);
  const frames = await chunk(index);
  if (index + 1 <= duration / CHUNK_S) chunk(index + 1).catch(() => {}); // prefetch
  let lo = 0, hi = frames.length - 1, best = frames.length ? 0 : -1;
  while (lo <= hi) { // the last frame at or before t
    const mid = (lo + hi) >> 1;
    if (frames[mid].t <= t + 1e-9) { best = mid; lo = mid + 1; } else hi = mid - 1;
  }
  if (best >= 0) showFrame(frames[best]);
}

async function seek(t) {
  simTime = Math.max(0, Math.min(t, duration));
  scrub.value = simTime;
  await showTime(simTime);
}
api.seek = seek;

function startReplay(run) {
  duration = run.sim_seconds;
  const play = document.getElementById("viewer-play");
  play.addEventListener("click", () => {
    playing = !playing;
    if (playing && simTime >= duration) simTime = 0;
    play.textContent = playing ? "Pause" : "Play";
  });
  document.getElementById("viewer-speed").addEventListener("change", (event) => {
    speed = Number(event.target.value);
  });
  scrub.addEventListener("input", () => seek(Number(scrub.value)));
  let last = performance.now(), busy = false;
  function tick(now) {
    const dt = (now - last) / 1000;
    last = now;
    if (playing && !busy) {
      simTime = Math.min(duration, simTime + dt * speed);
      scrub.value = simTime;
      busy = true;
      showTime(simTime).catch((error) => status(`frames: ${error.message}`)).finally(() => { busy = false; });
      if (simTime >= duration) { playing = false; document.getElementById("viewer-play").textContent = "Play"; }
    }
    requestAnimationFrame(tick);
  }
  requestAnimationFrame(tick);
  status("replay");
  return seek(0);
}

// -- live -----------------------------------------------------------------------------------
function startLive() {
  const viewer = Math.random().toString(36).slice(2);
  const delay = Number(box.dataset.delayMs) / 1000;
  const pollMs = Math.max(2 * Number(box.dataset.pollMs), 400);
  const buffer = [];
  let newest = -1, playT = null, last = performance.now();
  async function poll() {
    try {
      const body = await getJSON(`${box.dataset.liveUrl}?after=${newest}&viewer=${viewer}`);
      for (const frame of body.frames) { buffer.push(frame); newest = Math.max(newest, frame.t); }
      document.getElementById("viewer-score").textContent = body.score;
      document.getElementById("viewer-falls").textContent = body.falls;
      drawMarks(body.events.filter((e) => e.event !== "run_start").map((e) => ({
        t: e.sim_time, kind: e.event, label: e.name || e.reason || e.event,
      })), Math.max(newest, 1));
      status(buffer.length ? `live (${delay.toFixed(1)} s behind)` : `live: waiting for the simulator (relay ${body.relay})`);
      if (body.state !== "running") { status(`the run is ${body.state}; replay it when it has ended`); return; }
    } catch (error) {
      status(`live: ${error.message}`);
    }
    setTimeout(poll, pollMs);
  }
  function tick(now) {
    const dt = (now - last) / 1000;
    last = now;
    if (buffer.length) {
      const target = newest - delay;
      playT = playT === null || Math.abs(target - playT) > 2 ? target : playT + dt;
      playT = Math.min(playT, newest);
      while (buffer.length > 1 && buffer[1].t <= playT) buffer.shift();
      if (buffer[0].t <= playT) showFrame(buffer[0]);
      scrub.max = newest; scrub.value = api.t;
    }
    requestAnimationFrame(tick);
  }
  requestAnimationFrame(tick);
  poll();
}

function render() {
  resize();
  follow();
  controls.update();
  renderer.render(scene, camera);
  requestAnimationFrame(render);
}

getJSON(box.dataset.sceneUrl).then(async (body) => {
  buildScene(body.scene);
  document.getElementById("viewer-score").textContent = body.run.score;
  document.getElementById("viewer-falls").textContent = body.run.falls;
  requestAnimationFrame(render);
  if (mode === "replay") {
    replayMarks = body.marks;
    drawMarks(body.marks, body.run.sim_seconds);
    await startReplay(body.run);
  } else {
    startLive();
  }
  api.ready = true;
}).catch((error) => {
  api.error = error.message;
  status(`could not load the scene: ${error.message}`);
});
