// The field app end to end: the real page (app/dist) in headless Chromium, talking through
// `tangent app --emulator`'s WebSocket bridge to the emulated caliper (the firmware under
// QEMU). One plot, in order: 20 trees and a held trigger; the cable pulled mid-plot (and
// mid-measurement) with readings made meanwhile; the tab closed and reopened with readings
// made meanwhile; every export compared byte for byte with `tangent log export`, and the
// field log imported into a fresh browser; the page opened offline. The invariant checked
// throughout: the stored readings are exactly the caliper's sequence numbers, each once.
//
// No test waits for time: the bridge's controls answer once the emulated caliper has done
// what they asked (with the readings' sequence numbers), and the page says which readings it
// holds (`li[data-seq]`) and up to which of the device's readings a history check found
// nothing missing (`body[data-synced]`). Before each test the caliper is brought to rest
// (`/control/idle`: nothing in flight, no stream) and the page to its last reading, so no
// test sees another's readings.
//
// Run by app/e2e/run.sh (which builds what it needs); TANGENT_SCREENSHOTS=DIR also saves the
// main screens at phone and tablet sizes, normal and sunlight mode.

import { test, before, beforeEach, after } from "node:test";
import assert from "node:assert/strict";
import { spawn, execFileSync } from "node:child_process";
import { mkdtempSync, readFileSync, rmSync, mkdirSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, resolve, dirname } from "node:path";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";

const root = resolve(dirname(fileURLToPath(import.meta.url)), "../..");
const tangent = process.env.TANGENT_BIN || join(root, "target/release/tangent");
const chromiumPath = process.env.CHROMIUM || "/usr/bin/chromium";
const FLAGS = [
  "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
  "--disable-background-networking", "--disable-component-update", "--disable-sync",
];
const WAIT = 60_000;

let server, base, work, context, page;

async function startServer() {
  server = spawn(tangent, ["app", "--emulator", "--listen", "127.0.0.1:0"], { stdio: ["ignore", "pipe", "inherit"] });
  base = await new Promise((resolveUrl, reject) => {
    let out = "";
    server.stdout.on("data", (d) => {
      out += d;
      const m = out.match(/field app: (http:\/\/\S+)/);
      if (m) resolveUrl(m[1]);
    });
    server.on("exit", (code) => reject(new Error(`tangent app exited (${code}): ${out}`)));
  });
}

// A control of the emulated caliper; answers once done: {seqs (the readings it made, null
// for a failed measurement), last_seq (the device's last reading)}.
async function control(action) {
  const r = await fetch(new URL(`control/${action}`, base));
  const body = await r.text();
  assert.equal(r.status, 200, `control/${action}: ${body}`);
  return JSON.parse(body);
}

// The readings a control made, each a reading (no failed measurement).
async function made(action) {
  const { seqs } = await control(action);
  assert.ok(seqs.every((s) => Number.isInteger(s)), `control/${action} measured: ${JSON.stringify(seqs)}`);
  return seqs;
}

async function openPage() {
  page = await context.newPage();
  page.on("pageerror", (e) => console.error("page error:", e.message));
  page.on("console", (m) => { if (m.type() === "error" || m.type() === "warning") console.error("page:", m.text()); });
  await page.goto(`${base}?transport=bridge&nosw`);
  await page.waitForSelector("body[data-ready='1']", { timeout: WAIT });
}

async function connect() {
  await page.click("#connect");
  await page.waitForSelector("body[data-link='connected']", { timeout: WAIT });
}

const readings = () => page.evaluate(() => Number(document.body.dataset.readings || 0));
const checks = () => page.evaluate(() => Number(document.body.dataset.checks || 0));

// Waits until `predicate(arg)` holds in the page; says what the page shows if it never does.
async function waitUntil(what, predicate, arg) {
  try {
    await page.waitForFunction(predicate, arg, { timeout: WAIT });
  } catch (e) {
    const seen = await page.evaluate(() => ({
      ...document.body.dataset,
      status: document.getElementById("status").textContent,
      message: document.getElementById("r-message").textContent,
    }));
    throw new Error(`waiting for ${what}: the page shows ${JSON.stringify(seen)}: ${e.message}`);
  }
}

// Waits until the page has stored and shown the reading `seq`.
const waitSeq = (seq) => waitUntil(`reading ${seq}`, (s) => document.querySelector(`#trees li[data-seq='${s}']`) !== null, seq);

// Waits until a history check of the page found nothing missing up to the device's reading
// `seq`: every reading up to it is stored, and any duplicate would have been stored by now.
const waitSynced = (seq) => waitUntil(`the page synced to ${seq}`, (s) => Number(document.body.dataset.synced ?? -1) >= s, seq);

const waitReadings = (n) => waitUntil(`${n} readings`, (want) => Number(document.body.dataset.readings || 0) >= want, n);

// The sequence numbers of the stored readings, read from IndexedDB itself.
function storedSeqs() {
  return page.evaluate(() => new Promise((ok, fail) => {
    const open = indexedDB.open("tangent-field");
    open.onsuccess = () => {
      const all = open.result.transaction("lines").objectStore("lines").getAll();
      all.onsuccess = () => { ok(all.result.filter((e) => e.kind === "tree").map((e) => e.seq)); open.result.close(); };
      all.onerror = () => fail(all.error);
    };
    open.onerror = () => fail(open.error);
  }));
}

// Each of the caliper's readings 1..n once, in order.
async function assertEachReadingOnce() {
  const seqs = await storedSeqs();
  const want = Array.from({ length: seqs.length }, (_, i) => i + 1);
  assert.deepEqual(seqs, want, "stored sequence numbers");
  return seqs.length;
}

async function download(selector, path) {
  const [dl] = await Promise.all([page.waitForEvent("download"), page.click(selector)]);
  await dl.saveAs(path);
  return readFileSync(path);
}

before(async () => {
  work = mkdtempSync(join(tmpdir(), "tangent-app-e2e-"));
  await startServer();
  context = await chromium.launchPersistentContext(join(work, "profile"), {
    executablePath: chromiumPath, headless: true, args: FLAGS, acceptDownloads: true,
    viewport: { width: 412, height: 915 },
  });
  await openPage();
});

// Each test starts with the caliper at rest and the page holding all it made.
beforeEach(async () => {
  const { last_seq: last } = await control("idle");
  const connected = page && !page.isClosed() && await page.evaluate(() => document.body.dataset.link === "connected");
  if (connected) await waitSynced(last);
});

after(async () => {
  if (context) await context.close();
  if (server) server.kill();
  if (work) rmSync(work, { recursive: true, force: true });
});

test("a plot of 20 trees measured, species by species, and a held trigger", async () => {
  await page.click("#new-plot");
  await page.fill("#plot-input", "P-017");
  await page.fill("#plot-note", "spruce stand, e2e");
  await page.click("#plot-start");
  await page.waitForFunction(() => document.getElementById("plot-id").textContent === "P-017");
  await connect();
  const species = ["PIAB", "PISY", "FASY", "PIAB"];
  for (let tree = 1; tree <= 20; tree++) {
    if (tree % 5 === 1) await page.click(`[data-species='${species[(tree - 1) / 5]}']`);
    // The caliper's trigger, and now and then the page's Measure button.
    if (tree % 4 === 0) {
      await page.click("#measure");
      await waitReadings(tree);
    } else {
      const [seq] = await made("trigger");
      await waitSeq(seq);
    }
    assert.equal(await readings(), tree, "readings stored");
    assert.equal(await page.textContent("#r-tree"), `Tree ${tree}`);
    if (tree === 5) {
      // The elliptic stem (the emulated camera's fifth scene): its flags in words.
      const said = await page.$$eval("#r-warnings li", (lis) => lis.map((li) => li.textContent));
      assert.ok(said.some((w) => /not round/.test(w)), `warnings: ${said}`);
    }
  }
  assert.equal(await page.textContent("#next-tree"), "21");
  const diameter = Number(await page.textContent("#r-diameter"));
  assert.ok(diameter > 50 && diameter < 700, `a stem's diameter on screen: ${diameter}`);
  assert.match(await page.textContent("#r-uncertainty"), /^± \d+\.\d mm/);
  // The tally: 20 trees in three species.
  assert.equal(await page.evaluate(() => document.body.dataset.trees), "20");
  const rows = await page.$$eval("#tally tr", (trs) => trs.map((tr) => tr.firstChild.textContent));
  assert.deepEqual(rows, ["PIAB", "PISY", "FASY"]);
  // The trigger held: readings stream under one tree with the running mean and spread,
  // released once the page shows them.
  await control("hold");
  await page.waitForSelector("#r-held:not([hidden])", { timeout: WAIT });
  assert.match(await page.textContent("#r-held"), /held: \d+ readings · mean \d+\.\d mm · spread \d+\.\d mm/);
  const streamed = await made("release");
  assert.ok(streamed.length >= 2, `readings streamed: ${streamed}`);
  await waitSynced(streamed.at(-1));
  assert.equal(await page.textContent("#r-tree"), "Tree 21");
  assert.equal(await page.evaluate(() => document.body.dataset.trees), "21");
  await assertEachReadingOnce();
});

test("undo and re-measure", async () => {
  const before = await readings();
  const [undone] = await made("trigger");
  await waitSeq(undone);
  assert.equal(await readings(), before + 1);
  assert.equal(await page.textContent("#r-tree"), "Tree 22");
  await page.click("#undo");
  await waitUntil("the undo", (n) => Number(document.body.dataset.readings) === n, before);
  assert.equal(await page.textContent("#next-tree"), "22");
  // Undo removed the reading from the plot, not from the caliper: it is not fetched again
  // (two history checks, so that one began after the undo).
  const checked = await checks();
  await waitUntil("two history checks", (n) => Number(document.body.dataset.checks || 0) >= n, checked + 2);
  assert.equal(await readings(), before);
  await page.click("#remeasure");
  await page.waitForSelector("#remeasure-note:not([hidden])", { timeout: WAIT });
  assert.match(await page.textContent("#remeasure-note"), /re-measures tree 21$/);
  const [again] = await made("trigger");
  await waitSeq(again);
  assert.equal(await readings(), before + 1);
  assert.equal(await page.textContent("#r-tree"), "Tree 21");
  assert.equal(await page.textContent("#next-tree"), "22");
  assert.equal(await page.evaluate(() => document.body.dataset.trees), "21");
  assert.ok((await page.$$("#trees li.superseded")).length >= 1, "the earlier reading of tree 21 is shown superseded");
});

test("the cable pulled mid-plot: readings made meanwhile arrive, none lost or twice", async () => {
  const seqsBefore = await storedSeqs();
  const n = seqsBefore.length;
  // The undone reading (seq of tree 22) stays undone: the caliper's numbers have a hole there.
  const top = Math.max(...seqsBefore);
  // A measurement in flight when the cable goes, then three while it is out.
  const inFlight = await made("cut?measuring=1");
  await page.waitForSelector("body[data-link='lost']", { timeout: WAIT });
  const meanwhile = await made("trigger?n=3");
  assert.deepEqual([...inFlight, ...meanwhile], [top + 1, top + 2, top + 3, top + 4], "the caliper's numbers");
  await control("plug");
  await page.waitForSelector("body[data-link='connected']", { timeout: WAIT });
  await waitSynced(top + 4);
  const seqs = await storedSeqs();
  assert.equal(seqs.length, n + 4, "four readings made around and during the cut");
  assert.equal(new Set(seqs).size, seqs.length, "no reading twice");
  assert.deepEqual(seqs.slice(0, n), seqsBefore, "the readings before the cut, untouched");
  assert.deepEqual(seqs.slice(n), [top + 1, top + 2, top + 3, top + 4], "the readings after the cut, in order");
  assert.equal(await page.textContent("#next-tree"), "26");
});

test("the tab closed mid-plot and reopened: nothing lost, readings made meanwhile fetched", async () => {
  const before = await storedSeqs();
  const n = before.length;
  const next = await page.textContent("#next-tree");
  await page.close();
  const meanwhile = await made("trigger?n=2");
  await openPage();
  assert.equal(await page.textContent("#plot-id"), "P-017");
  assert.equal(await page.textContent("#next-tree"), next);
  assert.equal(await readings(), n, "every stored reading is back");
  await connect();
  await waitSynced(meanwhile.at(-1));
  assert.deepEqual(await storedSeqs(), [...before, ...meanwhile], "every reading once, the two made meanwhile fetched");
  // And a reload with nothing new brings nothing new (its first history check is done).
  await page.reload();
  await page.waitForSelector("body[data-ready='1']", { timeout: WAIT });
  await connect();
  await waitSynced(meanwhile.at(-1));
  assert.equal(await readings(), n + 2);
  assert.deepEqual(await storedSeqs(), [...before, ...meanwhile]);
});

test("exports are byte for byte what `tangent log export` writes; the log imports", async () => {
  const log = join(work, "tangent-field.log");
  await download("#download-log", log);
  const check = execFileSync(tangent, ["log", "check", "--log", log], { encoding: "utf8" });
  assert.match(check, /the log is intact/);
  for (const format of ["csv", "tsv", "json"]) {
    const fromApp = await download(`[data-export='${format}']`, join(work, `app.${format}`));
    const fromCli = execFileSync(tangent, ["log", "export", "--format", format, "--log", log]);
    assert.ok(fromApp.length > 500, `${format} export has content`);
    assert.ok(Buffer.compare(fromApp, fromCli) === 0, `${format}: the app's export differs from tangent log export's`);
  }
  // A fresh browser imports the log and exports the same bytes.
  const other = await chromium.launchPersistentContext(join(work, "profile2"), {
    executablePath: chromiumPath, headless: true, args: FLAGS, acceptDownloads: true,
  });
  try {
    const p = await other.newPage();
    await p.goto(`${base}?transport=bridge&nosw`);
    await p.waitForSelector("body[data-ready='1']", { timeout: WAIT });
    await p.setInputFiles("#import", log);
    await p.waitForFunction(() => Number(document.body.dataset.readings || 0) > 20, null, { timeout: WAIT });
    assert.equal(await p.textContent("#plot-id"), "P-017");
    const [dl] = await Promise.all([p.waitForEvent("download"), p.click("[data-export='csv']")]);
    const reimported = join(work, "reimported.csv");
    await dl.saveAs(reimported);
    assert.ok(Buffer.compare(readFileSync(reimported), readFileSync(join(work, "app.csv"))) === 0);
  } finally {
    await other.close();
  }
});

test("screens at phone and tablet sizes, normal and sunlight", async () => {
  const dir = process.env.TANGENT_SCREENSHOTS || join(work, "screens");
  mkdirSync(dir, { recursive: true });
  const [seq] = await made("trigger");
  await waitSeq(seq);
  for (const [name, viewport] of [["phone", { width: 412, height: 915 }], ["tablet", { width: 1280, height: 800 }]]) {
    await page.setViewportSize(viewport);
    for (const sun of [false, true]) {
      await page.evaluate((on) => { document.body.classList.toggle("sun", on); window.scrollTo(0, 0); }, sun);
      const file = join(dir, `${name}${sun ? "-sun" : ""}.png`);
      await page.screenshot({ path: file });
      // The diameter fits the screen: readable at arm's length.
      const box = await page.locator("#r-diameter").boundingBox();
      assert.ok(box && box.width < viewport.width && box.height >= 60, `${name}: diameter ${JSON.stringify(box)}`);
    }
  }
  await page.evaluate(() => document.body.classList.remove("sun"));
});

test("the app opens offline once visited", async () => {
  const p = await context.newPage();
  try {
    await p.goto(`${base}?transport=bridge`);
    await p.waitForSelector("body[data-ready='1']", { timeout: WAIT });
    await p.evaluate(() => navigator.serviceWorker.ready.then(() => true));
    await context.setOffline(true);
    await p.reload();
    await p.waitForSelector("body[data-ready='1']", { timeout: WAIT });
    assert.equal(await p.textContent("#plot-id"), "P-017", "the plot, from IndexedDB, offline");
  } finally {
    await context.setOffline(false);
    await p.close();
  }
});
