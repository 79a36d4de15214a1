// The page's link to the caliper: what `tangent listen`'s link does (host/src/link.rs), in
// the browser. The protocol (frames, CRC, messages, failure sentences) and the order of
// readings (each once; gaps asked for from the device's history) are the WebAssembly
// core's; this file only moves bytes, keeps time and re-opens a lost port.
//
// Transports: Web Serial (the caliper's USB CDC port, chosen in the browser's port picker)
// or a WebSocket to `tangent app`'s bridge (a serial port or the emulated caliper).

const REPLY_TIMEOUT_MS = 1500;
const ATTEMPTS = 4;
const IDLE_CHECK_MS = 1000;
const RECONNECT_EVERY_MS = 500;

export class WebSocketTransport {
  constructor(url) { this.url = url; this.name = "bridge"; }
  open(onBytes, onClose) {
    return new Promise((resolve, reject) => {
      const ws = new WebSocket(this.url);
      ws.binaryType = "arraybuffer";
      let opened = false;
      ws.onopen = () => { opened = true; this.ws = ws; resolve(); };
      ws.onmessage = (e) => onBytes(new Uint8Array(e.data));
      ws.onclose = () => { if (opened) onClose("the bridge closed"); else reject(new Error("the bridge refused the connection")); };
      ws.onerror = () => {};
    });
  }
  async write(bytes) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) throw new Error("not connected");
    this.ws.send(bytes);
  }
  close() { if (this.ws) this.ws.close(); }
}

export class WebSerialTransport {
  constructor(port) { this.port = port; this.name = "usb"; this.info = port.getInfo(); }
  async open(onBytes, onClose) {
    if (!this.port) await this.findAgain();
    await this.port.open({ baudRate: 115200 });
    this.closed = false;
    const reader = this.port.readable.getReader();
    this.reader = reader;
    (async () => {
      try {
        for (;;) {
          const { value, done } = await reader.read();
          if (done) break;
          if (value) onBytes(value);
        }
      } catch (e) { /* unplugged */ }
      try { reader.releaseLock(); } catch (e) {}
      try { await this.port.close(); } catch (e) {}
      if (!this.closed) { this.port = null; onClose("the cable was pulled"); }
    })();
  }
  // After an unplug the browser hands out a new port object for the same caliper.
  async findAgain() {
    const ports = await navigator.serial.getPorts();
    const same = ports.find((p) => {
      const i = p.getInfo();
      return i.usbVendorId === this.info.usbVendorId && i.usbProductId === this.info.usbProductId;
    });
    if (!same) throw new Error("the caliper is not plugged in");
    this.port = same;
  }
  async write(bytes) {
    if (!this.port || !this.port.writable) throw new Error("not connected");
    const w = this.port.writable.getWriter();
    try { await w.write(bytes); } finally { w.releaseLock(); }
  }
  close() {
    this.closed = true;
    if (this.reader) this.reader.cancel().catch(() => {});
  }
}

export class Link {
  // handlers: onReading(r) → Promise (store, then show), onState(state, text),
  // onFailure(text), onLost(from, to), resumeFrom(identity) → stored last seq or null,
  // onSynced(lastSeq) (optional: a history check found nothing missing up to the device's
  // last reading).
  constructor(core, transport, handlers) {
    this.core = core;
    this.transport = transport;
    this.h = handlers;
    this.nextTag = 1;
    this.pending = new Map();
    this.identity = null;
    this.connected = false;
    this.streaming = false;
    this.recovering = null;
    this.lastFrameAt = 0;
    this.lastCheckAt = 0;
    this.drainChain = Promise.resolve();
    this.counters = { frames: 0, rejected: 0, duplicates: 0, reconnects: 0, lost: 0 };
    this.stopped = false;
  }

  async connect() {
    await this.open();
    this.timer = setInterval(() => this.tick(), 250);
  }

  async open() {
    this.core.resetDecoder();
    await this.transport.open((b) => this.onBytes(b), (why) => this.onClose(why));
    this.connected = true;
    await this.transport.write(new Uint8Array([0])); // ends the device's partial frame
    const was = this.identity;
    const reply = await this.request("DeviceInfo", true);
    const info = reply.response.Info;
    if (!info) throw new Error("the device did not identify itself");
    if (info.protocol_version !== this.core.constants.protocol_version) {
      throw new Error(`the device speaks protocol version ${info.protocol_version}, this app speaks version ${this.core.constants.protocol_version}`);
    }
    this.identity = { ...info, device_id: reply.device_id };
    if (!was) {
      // First contact: carry on after the last reading stored from this device (readings
      // made while the page was closed come from its history), else after its current last.
      const stored = await this.h.resumeFrom(this.identity);
      this.core.resumeAfter(stored ?? info.last_seq);
    } else if (info.last_seq < this.core.lastSeq() || info.uptime_ms < this.core.newestMs()) {
      this.rebooted();
    }
    this.h.onState("connected", `${this.identity.device_id} · firmware ${info.fw_version} · calibration ${info.calib_id ?? "none"}`);
    if (this.streaming) await this.request("StartStream", true);
    await this.recover();
  }

  rebooted() {
    this.core.restart();
    this.streaming = false;
    this.h.onFailure("the caliper restarted");
  }

  onClose(why) {
    if (!this.connected) return;
    this.connected = false;
    for (const p of this.pending.values()) p.reject(new Error("link lost"));
    this.pending.clear();
    if (this.stopped) return;
    this.h.onState("lost", `link lost (${why}); waiting for the caliper…`);
    this.reconnectLoop();
  }

  async reconnectLoop() {
    while (!this.stopped && !this.connected) {
      await sleep(RECONNECT_EVERY_MS);
      try {
        await this.open();
        this.counters.reconnects += 1;
        return;
      } catch (e) {
        this.connected = false;
        try { this.transport.close(); } catch (_) {}
      }
    }
  }

  disconnect() {
    this.stopped = true;
    clearInterval(this.timer);
    this.connected = false;
    this.transport.close();
    this.h.onState("off", "not connected");
  }

  onBytes(bytes) {
    for (const ev of this.core.feed(bytes)) {
      if (ev.rejected !== undefined) { this.counters.rejected += 1; continue; }
      this.counters.frames += 1;
      this.lastFrameAt = performance.now();
      if (ev.duplicate) this.counters.duplicates += 1;
      const r = ev.response;
      const waiting = this.pending.get(ev.tag);
      const isReplay = r.Reading !== undefined && waiting && waiting.request !== "Measure";
      if (waiting && !isReplay) {
        this.pending.delete(ev.tag);
        waiting.resolve(ev);
      } else if (ev.tag === 0 && r.Info) {
        // The boot banner: the caliper restarted.
        if (this.core.lastSeq() > 0) this.rebooted();
      }
      if (r.Error && r.Error.code === "MeasurementFailed" && !waiting) this.h.onFailure(ev.text);
    }
    this.drain();
  }

  // Files the readings the core has in order, one at a time (each is stored before the next).
  drain() {
    if (this.draining) return;
    this.draining = true;
    this.drainChain = this.drainChain.then(async () => {
      try {
        let r;
        while ((r = this.core.popReading()) !== null) await this.h.onReading(r);
      } finally {
        this.draining = false;
      }
    });
  }

  async write(bytes) {
    try {
      await this.transport.write(bytes);
    } catch (e) {
      this.onClose(e.message);
      throw e;
    }
  }

  // Sends `request` and waits for the reply with its tag; re-sends idempotent ones.
  async request(request, idempotent) {
    const attempts = idempotent ? ATTEMPTS : 1;
    for (let i = 0; i < attempts; i++) {
      if (!this.connected) throw new Error("not connected");
      const tag = this.nextTag;
      this.nextTag = this.nextTag >= 0xffff ? 1 : this.nextTag + 1;
      const reply = new Promise((resolve, reject) => {
        this.pending.set(tag, { resolve, reject, request });
        setTimeout(() => { if (this.pending.delete(tag)) resolve(null); }, REPLY_TIMEOUT_MS);
      });
      await this.write(this.core.encode(tag, request));
      const ev = await reply;
      if (ev) return ev;
    }
    const what = typeof request === "string" ? request : Object.keys(request)[0];
    throw new Error(`no answer to ${what} after ${attempts} attempt(s)`);
  }

  // Asks for the readings after the last one; the core gives up those the device no longer has.
  recover() {
    if (!this.recovering) {
      this.recovering = this.recoverOnce().finally(() => { this.recovering = null; });
    }
    return this.recovering;
  }

  async recoverOnce() {
    this.lastCheckAt = performance.now();
    const after = this.core.historyRequested();
    const ev = await this.request({ History: { after_seq: after } }, true);
    const end = ev.response.HistoryEnd;
    if (!end) throw new Error("unexpected answer to History");
    const outcome = this.core.historyEnded(after, end.last_seq);
    if (outcome.rebooted) {
      this.rebooted();
      return this.recoverOnce();
    }
    for (const [from, to] of outcome.lost) {
      this.counters.lost += to - from + 1;
      this.h.onLost(from, to);
    }
    this.drain();
    // Everything up to the device's last reading is now filed (or reported lost).
    await this.drainChain;
    if (this.h.onSynced) this.h.onSynced(end.last_seq);
  }

  tick() {
    if (!this.connected || this.recovering) return;
    const now = performance.now();
    const idle = now - this.lastFrameAt >= IDLE_CHECK_MS && now - this.lastCheckAt >= IDLE_CHECK_MS;
    if (this.core.hasGap() || idle) this.recover().catch(() => {});
  }

  // A trigger press from the page. The reading itself arrives like any other (a reply lost
  // on the wire is recovered from the history rather than measured twice).
  async measure() {
    try {
      const ev = await this.request("Measure", false);
      if (ev.response.Error) this.h.onFailure(ev.text);
    } catch (e) {
      if (this.connected) await this.recover();
      else throw e;
    }
  }

  async startStream() {
    this.streaming = true;
    const ev = await this.request("StartStream", true);
    if (ev.response.Error) { this.streaming = false; this.h.onFailure(ev.text); }
  }

  async stopStream() {
    this.streaming = false;
    await this.request("StopStream", true);
  }
}

export function sleep(ms) {
  return new Promise((r) => setTimeout(r, ms));
}
