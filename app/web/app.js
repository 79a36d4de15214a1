// The field app: plots, trees, species, the tally, export — everything format-shaped comes
// from the WebAssembly core (core.js), every reading is in IndexedDB (store.js) before it
// is shown, and the link (link.js) recovers what a pulled cable or a closed tab missed.

import { Core } from "./core.js";
import { Store } from "./store.js";
import { Link, WebSerialTransport, WebSocketTransport } from "./link.js";

const $ = (id) => document.getElementById(id);
const DEFAULT_SPECIES = ["PIAB", "PISY", "FASY", "QUPE", "BEPE", "ALGL"];

const state = {
  core: null,
  store: null,
  link: null,
  entries: [], // the stored lines, in order (what the field log holds)
  plot: null, // {plot_id, started, note}
  nextTree: 1,
  species: "",
  speciesList: DEFAULT_SPECIES,
  remeasure: null,
  lastTree: null,
  beep: true,
};

// ---- start-up ----------------------------------------------------------------------------

async function main() {
  state.core = await Core.load();
  state.store = await Store.open();
  state.entries = await state.store.all();
  state.plot = await state.store.get("plot", null);
  state.nextTree = await state.store.get("next_tree", 1);
  state.species = await state.store.get("species", "");
  state.speciesList = await state.store.get("species_list", DEFAULT_SPECIES);
  state.remeasure = await state.store.get("remeasure", null);
  state.beep = await state.store.get("beep", true);
  setSunlight(await state.store.get("sunlight", false));
  const params = new URLSearchParams(location.search);
  $("transport").value = params.get("transport") || ("serial" in navigator ? "usb" : "bridge");
  wire();
  renderAll();
  if ("serviceWorker" in navigator && !params.has("nosw")) {
    navigator.serviceWorker.register("sw.js").catch(() => {});
  }
  document.body.dataset.ready = "1";
}

function wire() {
  $("connect").onclick = () => (state.link ? disconnect() : connect());
  $("sun").onclick = () => setSunlight(!document.body.classList.contains("sun"), true);
  $("new-plot").onclick = () => { $("plot-input").value = suggestPlotId(); $("plot-dialog").showModal(); };
  $("plot-dialog").onclose = () => { if ($("plot-dialog").returnValue === "start") startPlot(); };
  $("settings").onclick = () => {
    $("species-input").value = state.speciesList.join(" ");
    $("beep-input").checked = state.beep;
    $("settings-dialog").showModal();
  };
  $("settings-dialog").onclose = () => { if ($("settings-dialog").returnValue === "save") saveSettings(); };
  $("tree-up").onclick = () => setNextTree(state.nextTree + 1);
  $("tree-down").onclick = () => setNextTree(Math.max(1, state.nextTree - 1));
  $("measure").onclick = () => state.link && state.link.measure().catch((e) => message(e.message));
  const hold = $("hold");
  hold.onpointerdown = () => state.link && state.link.startStream().catch((e) => message(e.message));
  const release = () => state.link && state.link.streaming && state.link.stopStream().catch(() => {});
  hold.onpointerup = release;
  hold.onpointerleave = release;
  $("undo").onclick = undo;
  $("remeasure").onclick = markRemeasure;
  for (const b of document.querySelectorAll("[data-export]")) b.onclick = () => exportAs(b.dataset.export);
  $("download-log").onclick = () => download("tangent-field.log", logText(), "text/plain");
  $("import").onchange = importLog;
}

// ---- the caliper -------------------------------------------------------------------------

async function connect() {
  let transport;
  try {
    if ($("transport").value === "usb") {
      const c = state.core.constants;
      const port = await navigator.serial.requestPort({ filters: [{ usbVendorId: c.usb_vendor_id, usbProductId: c.usb_product_id }] });
      transport = new WebSerialTransport(port);
    } else {
      transport = new WebSocketTransport(new URL("bridge", location.href).href.replace(/^http/, "ws"));
    }
  } catch (e) {
    return message(`no caliper chosen (${e.message})`);
  }
  const link = new Link(state.core, transport, {
    onReading,
    onState,
    onFailure: (text) => { message(text); beep(false); },
    onLost: (from, to) => message(`readings ${from}–${to} were made while disconnected and are no longer on the caliper`),
    // For tests and tools: the page holds every reading up to `data-synced` (the device's
    // last, at its last history check); `data-checks` counts those checks.
    onSynced: (lastSeq) => {
      document.body.dataset.synced = String(lastSeq);
      document.body.dataset.checks = String(Number(document.body.dataset.checks || 0) + 1);
    },
    resumeFrom: async (id) => {
      const last = await state.store.get(`device:${id.device_id}`, null);
      // Same boot of the caliper (its clock and numbers are past ours): carry on after it.
      return last && last.device_time_ms <= id.uptime_ms && last.seq <= id.last_seq ? last.seq : null;
    },
  });
  state.link = link;
  $("connect").textContent = "Disconnect";
  onState("connecting", "connecting…");
  try {
    await link.connect();
  } catch (e) {
    link.disconnect();
    state.link = null;
    $("connect").textContent = "Connect caliper";
    message(`cannot connect: ${e.message}`);
  }
}

function disconnect() {
  state.link.disconnect();
  state.link = null;
  $("connect").textContent = "Connect caliper";
}

function onState(kind, text) {
  const s = $("status");
  s.className = `status ${kind}`;
  s.textContent = text;
  document.body.dataset.link = kind;
}

// A reading from the caliper, in order, once: stored, then shown.
async function onReading(r) {
  const reading = r.reading;
  const deviceId = state.link.identity.device_id;
  if (await state.store.has(deviceId, reading.seq, reading.timestamp_ms)) {
    // Stored before the page was reloaded (or imported): the core files it no more.
    await state.store.set({ [`device:${deviceId}`]: { seq: reading.seq, device_time_ms: reading.timestamp_ms } });
    return;
  }
  if (!state.plot) await startPlotWith(suggestPlotId(), "");
  const held = reading.stats && reading.stats.count > 1 && state.lastTree !== null;
  let tree;
  if (held) tree = state.lastTree;
  else if (state.remeasure !== null) { tree = state.remeasure; state.remeasure = null; }
  else { tree = state.nextTree; state.nextTree += 1; }
  const filed = state.core.file({
    plot_id: state.plot.plot_id,
    tree_id: tree,
    species: state.species,
    device_id: deviceId,
    time: new Date().toISOString().replace(/\.\d+Z$/, "Z"),
  });
  const entry = {
    line: filed.line, kind: "tree", plot_id: state.plot.plot_id, tree_id: tree,
    device_id: deviceId, seq: reading.seq, device_time_ms: reading.timestamp_ms,
    record: filed.record,
  };
  const [id] = await state.store.append([entry], {
    [`device:${deviceId}`]: { seq: reading.seq, device_time_ms: reading.timestamp_ms },
    next_tree: state.nextTree,
    remeasure: state.remeasure,
  });
  entry.id = id;
  state.entries.push(entry);
  state.lastTree = tree;
  showReading(filed.record, r);
  beep(true);
  renderAll();
}

// ---- plots, trees, species ----------------------------------------------------------------

function suggestPlotId() {
  const ids = state.entries.filter((e) => e.kind === "plot").map((e) => e.plot_id);
  let n = ids.length + 1;
  while (ids.includes(String(n))) n++;
  return String(n);
}

async function startPlot() {
  const id = $("plot-input").value.trim();
  if (!id) return;
  let note = $("plot-note").value.trim();
  if ($("plot-gps-input").checked) {
    const gps = await position().catch((e) => `GPS unavailable: ${e.message}`);
    note = note ? `${gps}; ${note}` : gps;
  }
  await startPlotWith(id, note);
}

function position() {
  return new Promise((resolve, reject) => {
    if (!navigator.geolocation) return reject(new Error("no GPS in this browser"));
    navigator.geolocation.getCurrentPosition(
      (p) => resolve(`GPS ${p.coords.latitude.toFixed(6)} ${p.coords.longitude.toFixed(6)} ±${Math.round(p.coords.accuracy)} m`),
      (e) => reject(new Error(e.message)),
      { enableHighAccuracy: true, timeout: 20000 },
    );
  });
}

async function startPlotWith(plotId, note) {
  const plot = { plot_id: plotId, started: new Date().toISOString().replace(/\.\d+Z$/, "Z"), note };
  const line = state.core.encodeRecord({ type: "plot", ...plot });
  const trees = state.entries.filter((e) => e.kind === "tree" && e.plot_id === plotId);
  const next = trees.reduce((m, e) => Math.max(m, e.tree_id), 0) + 1;
  const entry = { line, kind: "plot", plot_id: plotId };
  const [id] = await state.store.append([entry], { plot, next_tree: next, remeasure: null });
  entry.id = id;
  state.entries.push(entry);
  state.plot = plot;
  state.nextTree = next;
  state.remeasure = null;
  state.lastTree = null;
  renderAll();
}

async function setNextTree(n) {
  state.nextTree = n;
  state.lastTree = null;
  await state.store.set({ next_tree: n });
  renderAll();
}

async function setSpecies(code) {
  state.species = code;
  await state.store.set({ species: code });
  renderAll();
}

async function undo() {
  if (!state.plot) return;
  const i = state.entries.findLastIndex((e) => e.kind === "tree" && e.plot_id === state.plot.plot_id);
  if (i < 0) return;
  const [gone] = state.entries.splice(i, 1);
  const trees = state.entries.filter((e) => e.kind === "tree" && e.plot_id === state.plot.plot_id);
  state.nextTree = trees.reduce((m, e) => Math.max(m, e.tree_id), 0) + 1;
  state.lastTree = null;
  await state.store.remove(gone.id, { next_tree: state.nextTree });
  message(`reading of tree ${gone.tree_id} removed`);
  renderAll();
}

async function markRemeasure() {
  const last = state.entries.findLast((e) => e.kind === "tree" && state.plot && e.plot_id === state.plot.plot_id);
  const n = state.remeasure !== null ? null : last ? last.tree_id : null;
  state.remeasure = n;
  state.lastTree = null;
  await state.store.set({ remeasure: n });
  renderAll();
}

async function saveSettings() {
  const codes = $("species-input").value.split(/\s+/).map((s) => s.trim().toUpperCase()).filter(Boolean);
  state.speciesList = codes.length ? codes : DEFAULT_SPECIES;
  state.beep = $("beep-input").checked;
  await state.store.set({ species_list: state.speciesList, beep: state.beep });
  renderAll();
}

function setSunlight(on, save) {
  document.body.classList.toggle("sun", on);
  $("sun").setAttribute("aria-pressed", String(on));
  if (save) state.store.set({ sunlight: on });
}

// ---- the field log ------------------------------------------------------------------------

function logText() {
  return state.core.constants.magic_line + state.entries.map((e) => e.line).join("");
}

function exportAs(format) {
  try {
    const text = state.core.exportLog(logText(), format);
    download(`tangent-field.${format}`, text, format === "json" ? "application/json" : "text/plain");
  } catch (e) {
    message(`cannot export: ${e.message}`);
  }
}

function download(name, text, type) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(new Blob([text], { type }));
  a.download = name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

async function importLog(ev) {
  const file = ev.target.files[0];
  ev.target.value = "";
  if (!file) return;
  const found = state.core.importLog(new Uint8Array(await file.arrayBuffer()));
  if (found.error) return message(`${file.name}: ${found.error}`);
  const fresh = [];
  let plot = null;
  for (let i = 0; i < found.records.length; i++) {
    const r = found.records[i];
    const entry = { line: found.lines[i], kind: r.type, plot_id: r.plot_id };
    if (r.type === "tree") {
      if (await state.store.has(r.device_id, r.seq, r.device_time_ms)) continue;
      Object.assign(entry, { tree_id: r.tree_id, device_id: r.device_id, seq: r.seq, device_time_ms: r.device_time_ms, record: r });
    } else {
      if (state.entries.some((e) => e.line === entry.line)) continue;
      plot = { plot_id: r.plot_id, started: r.started, note: r.note || "" };
    }
    fresh.push(entry);
  }
  const meta = plot ? { plot } : {};
  const ids = await state.store.append(fresh, meta);
  fresh.forEach((e, i) => { e.id = ids[i]; });
  state.entries.push(...fresh);
  if (plot) {
    state.plot = plot;
    const trees = state.entries.filter((e) => e.kind === "tree" && e.plot_id === plot.plot_id);
    await setNextTree(trees.reduce((m, e) => Math.max(m, e.tree_id), 0) + 1);
  }
  const notes = found.findings.length ? ` (${found.findings.join("; ")})` : "";
  message(`${file.name}: ${fresh.length} record(s) imported${notes}`);
  renderAll();
}

// ---- showing ------------------------------------------------------------------------------

function showReading(record, r) {
  $("r-tree").textContent = `Tree ${record.tree_id}`;
  $("r-species").textContent = record.species || "";
  $("r-diameter").textContent = record.diameter_mm.toFixed(1);
  $("r-uncertainty").textContent = `± ${record.uncertainty_mm.toFixed(1)} mm · ${r.method}${record.tilt_deg ? ` · tilt ${record.tilt_deg.toFixed(1)}°` : ""}`;
  const stats = r.reading.stats;
  const held = $("r-held");
  held.hidden = !(stats && stats.count > 1);
  if (!held.hidden) {
    held.textContent = `held: ${stats.count} readings · mean ${(stats.mean_m * 1e3).toFixed(1)} mm · spread ${(stats.spread_m * 1e3).toFixed(1)} mm`;
  }
  const ul = $("r-warnings");
  ul.replaceChildren(...r.warnings.map((w) => Object.assign(document.createElement("li"), { textContent: w })));
  $("reading").classList.toggle("warn", r.warnings.length > 0);
  $("r-message").hidden = true;
}

function message(text) {
  const m = $("r-message");
  m.textContent = text;
  m.hidden = false;
}

function renderAll() {
  $("plot-id").textContent = state.plot ? state.plot.plot_id : "—";
  $("plot-gps").textContent = state.plot && state.plot.note ? state.plot.note : "";
  $("next-tree").textContent = state.nextTree;
  const box = $("species");
  box.replaceChildren(...["", ...state.speciesList].map((code) => {
    const b = document.createElement("button");
    b.textContent = code || "none";
    b.setAttribute("role", "radio");
    b.setAttribute("aria-checked", String(code === state.species));
    b.dataset.species = code;
    b.onclick = () => setSpecies(code);
    return b;
  }));
  const note = $("remeasure-note");
  note.hidden = state.remeasure === null;
  note.textContent = `next reading re-measures tree ${state.remeasure}`;
  $("remeasure").classList.toggle("on", state.remeasure !== null);
  renderTally();
}

function renderTally() {
  const body = $("tally");
  const list = $("trees");
  if (!state.plot) { body.replaceChildren(); $("tally-total").replaceChildren(); list.replaceChildren(); return; }
  const { tally, trees } = state.core.tally(logText(), state.plot.plot_id);
  const row = (t, tag = "td") => {
    const tr = document.createElement("tr");
    for (const v of [t.species || "–", t.count, t.mean_mm.toFixed(1), t.quadratic_mean_mm.toFixed(1), t.basal_area_m2.toFixed(3)]) {
      tr.append(Object.assign(document.createElement(tag), { textContent: v }));
    }
    return tr;
  };
  body.replaceChildren(...tally.species.map((s) => row(s)));
  $("tally-total").replaceChildren(row({ ...tally.total, species: "all" }, "th"));
  const counts = new Set(trees.map((t) => `${t.tree_id}/${t.seq}/${t.device_time_ms}`));
  const items = state.entries
    .filter((e) => e.kind === "tree" && e.plot_id === state.plot.plot_id)
    .slice(-60)
    .reverse()
    .map((e) => {
      const rec = e.record;
      const li = document.createElement("li");
      li.textContent = `tree ${rec.tree_id} ${rec.species || "–"} ${rec.diameter_mm.toFixed(1)} mm ± ${rec.uncertainty_mm.toFixed(1)}`;
      li.dataset.seq = rec.seq;
      if (!counts.has(`${rec.tree_id}/${rec.seq}/${rec.device_time_ms}`)) li.className = "superseded";
      return li;
    });
  list.replaceChildren(...items);
  document.body.dataset.trees = String(tally.total.count);
  document.body.dataset.readings = String(state.entries.filter((e) => e.kind === "tree").length);
}

let audio = null;
function beep(ok) {
  if (!state.beep) return;
  try {
    audio = audio || new AudioContext();
    const o = audio.createOscillator();
    const g = audio.createGain();
    o.frequency.value = ok ? 2200 : 440;
    g.gain.value = 0.2;
    o.connect(g).connect(audio.destination);
    o.start();
    o.stop(audio.currentTime + (ok ? 0.12 : 0.4));
  } catch (e) { /* no audio output */ }
}

main().catch((e) => {
  document.body.dataset.ready = "error";
  message(`the app could not start: ${e.message}`);
});
