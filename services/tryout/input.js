// sctd's pages as an input device (sctd try, sctd study run): the gamepad (Gamepad API),
// the keyboard and the on-screen stick read and sent as raw readings over the page's socket
// (window.sctdSocket), 50 times a second; nothing but "stale" while the page is hidden or
// unfocused. The page that loads this (and input.css) has an empty <div id="pads">, which
// this fills with the on-screen stick, its z pad and buttons, and may set window.sctdCapture to a function saying whether the keys are the arm's now (a
// form on the page keeps its keys otherwise).
"use strict";
const RATE_MS = 20;  // a reading every 20 ms (50 Hz); the daemon's input timeout is 0.1 s
const $ = (id) => document.getElementById(id);
let seq = 0, paused = null, blurred = false;
const keys = new Set();
const touch = { stick: null, z: null, x: 0, y: 0, zv: 0, buttons: [0, 0, 0, 0, 0, 0] };
window.sctdCapture = () => true;
$("pads").innerHTML = `
  <div id="stick" title="on-screen stick: press and drag (x, y); lifting the finger stops"><div class="knob"></div></div>
  <div id="zpad" title="z: press and drag up or down"><div class="knob"></div></div>
  <div id="buttons">
    <button data-b="0">mode</button><button data-b="2">escape</button>
    <button data-b="5">grasp</button><button data-b="3">stop</button>
  </div>`;

function bar(x) {  // an input axis in [-1, 1] as a bar and its value
  const w = Math.abs(x) * 50, left = x >= 0 ? 50 : 50 - w;
  return `<span class="bar"><i style="left:${left}%;width:${w}%"></i></span> ${x.toFixed(2)}`;
}

function send(msg) {
  const ws = window.sctdSocket;
  if (ws && ws.readyState === 1) ws.send(JSON.stringify(msg));
}

// -- staleness: hidden or unfocused, the page sends nothing but "stale" ----------------------
function whyStale() {
  if (document.visibilityState === "hidden") return "hidden";
  if (blurred || !document.hasFocus()) return "blur";
  return null;
}
function checkStale() {
  const why = whyStale();
  if (why && paused !== why) { paused = why; keys.clear(); send({ type: "stale", why }); }
  else if (!why && paused) { paused = null; send({ type: "resume" }); }
}
document.addEventListener("visibilitychange", checkStale);
window.addEventListener("blur", () => { blurred = true; checkStale(); });
window.addEventListener("focus", () => { blurred = false; checkStale(); });

// -- the devices ----------------------------------------------------------------------------
const KEYS = ["ArrowRight", "ArrowLeft", "ArrowUp", "ArrowDown", "KeyW", "KeyS", "PageUp", "PageDown",
              "Space", "KeyM", "KeyE", "KeyX", "KeyC", "KeyG", "ShiftLeft", "ShiftRight"];
window.addEventListener("keydown", (e) => {
  if (KEYS.includes(e.code) && window.sctdCapture()) { keys.add(e.code); e.preventDefault(); }
});
window.addEventListener("keyup", (e) => { keys.delete(e.code); });
const k = (...codes) => (codes.some((c) => keys.has(c)) ? 1 : 0);
function keyboardReading() {
  return { source: "keyboard",
           axes: [k("ArrowRight") - k("ArrowLeft"), k("ArrowUp") - k("ArrowDown"),
                  k("KeyW", "PageUp") - k("KeyS", "PageDown")],
           buttons: [k("Space", "KeyM"), k("ShiftLeft", "ShiftRight"), k("KeyE"), k("KeyX"), k("KeyC"), k("KeyG")] };
}
function standardPad() {
  const pads = navigator.getGamepads ? Array.from(navigator.getGamepads() || []) : [];
  return pads.find((p) => p && p.connected !== false && p.mapping === "standard") || null;
}
function padReading(pad) {
  return { source: "gamepad", axes: Array.from(pad.axes).slice(0, 8).map(Number),
           buttons: Array.from(pad.buttons).slice(0, 24).map((b) => (b && b.pressed ? 1 : 0)) };
}
function touchReading() {
  const b = touch.buttons.slice();
  b[1] = touch.stick !== null || touch.z !== null ? 1 : 0;
  return { source: "touch", axes: [touch.x, touch.y, touch.zv], buttons: b };
}
function reading() {
  const pad = standardPad();
  if (pad && pad.buttons[5] && pad.buttons[5].pressed) return padReading(pad);
  if (touch.stick !== null || touch.z !== null) return touchReading();
  if (keys.has("ShiftLeft") || keys.has("ShiftRight")) return keyboardReading();
  if (pad) return padReading(pad);
  if (touch.buttons.some((x) => x)) return touchReading();
  return keyboardReading();
}
setInterval(() => {
  checkStale();
  const ws = window.sctdSocket;
  if (paused || !ws || ws.readyState !== 1) return;
  seq += 1;
  send({ type: "input", seq, ...reading() });
}, RATE_MS);

// the on-screen stick and z pad (pointer events; a finger on either is the deadman)
function clampUnit(x, y) { const n = Math.hypot(x, y); return n > 1 ? [x / n, y / n] : [x, y]; }
function drag(el, which, update) {
  el.addEventListener("pointerdown", (e) => { touch[which] = e.pointerId; el.setPointerCapture(e.pointerId);
                                              el.classList.add("held"); update(e); e.preventDefault(); });
  el.addEventListener("pointermove", (e) => { if (touch[which] === e.pointerId) update(e); });
  const end = (e) => { if (touch[which] !== e.pointerId) return; touch[which] = null; el.classList.remove("held");
                       update(null); };
  el.addEventListener("pointerup", end);
  el.addEventListener("pointercancel", end);
  el.addEventListener("lostpointercapture", end);
}
drag($("stick"), "stick", (e) => {
  const knob = $("stick").firstElementChild;
  if (e === null) { touch.x = touch.y = 0; knob.style.transform = ""; return; }
  const r = $("stick").getBoundingClientRect(), R = r.width / 2;
  const [x, y] = clampUnit((e.clientX - r.left - R) / R, -(e.clientY - r.top - R) / R);
  touch.x = x; touch.y = y;
  knob.style.transform = `translate(${x * (R - 22)}px, ${-y * (R - 22)}px)`;
});
drag($("zpad"), "z", (e) => {
  const knob = $("zpad").firstElementChild;
  if (e === null) { touch.zv = 0; knob.style.transform = ""; return; }
  const r = $("zpad").getBoundingClientRect(), H = r.height / 2;
  touch.zv = Math.max(-1, Math.min(1, -(e.clientY - r.top - H) / (H - 20)));
  knob.style.transform = `translateY(${-touch.zv * (H - 20)}px)`;
});
for (const b of document.querySelectorAll("#buttons button")) {
  const i = Number(b.dataset.b);
  b.addEventListener("pointerdown", (e) => { touch.buttons[i] = 1; b.classList.add("held"); e.preventDefault(); });
  for (const ev of ["pointerup", "pointercancel", "pointerleave"]) {
    b.addEventListener(ev, () => { touch.buttons[i] = 0; b.classList.remove("held"); });
  }
}
