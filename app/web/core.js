// The loader of the field app's WebAssembly core (app/wasm: tangent-core's protocol and
// tangent-field's field log). It only moves bytes: arguments into the module's input slots,
// results out of its output buffer (docs/field-app.md, "The core's ABI").

const enc = new TextEncoder();
const dec = new TextDecoder();

export class Core {
  static async load(url = "tangent.wasm") {
    const bytes = await (await fetch(url)).arrayBuffer();
    const { instance } = await WebAssembly.instantiate(bytes, {});
    return new Core(instance.exports);
  }

  constructor(exports) {
    this.x = exports;
    this.constants = this.json(this.x.tg_constants());
  }

  // Copies `data` (string or bytes) into input slot `slot`.
  input(slot, data) {
    const bytes = typeof data === "string" ? enc.encode(data) : data;
    const ptr = this.x.tg_input(slot, bytes.length);
    new Uint8Array(this.x.memory.buffer, ptr, bytes.length).set(bytes);
  }

  // The output buffer (copied: the module's memory may move).
  output() {
    const ptr = this.x.tg_output_ptr();
    const len = this.x.tg_output_len();
    return new Uint8Array(this.x.memory.buffer, ptr, len).slice();
  }

  // The output as text; a status of 1 means it is an error sentence.
  text(status) {
    const t = dec.decode(this.output());
    if (status !== 0) throw new Error(t);
    return t;
  }

  json(status) {
    return JSON.parse(this.text(status));
  }

  // ---- the link -------------------------------------------------------------------------
  // A request (JSON of the core's `Request`: "Measure", {History: {after_seq: 4}}) as a frame.
  encode(tag, request) {
    this.input(0, JSON.stringify(request));
    const status = this.x.tg_encode(tag);
    if (status !== 0) this.text(status);
    return this.output();
  }
  // Bytes from the device → what they held: [{tag, response, text?, duplicate?} | {rejected}].
  feed(bytes) {
    this.input(0, bytes);
    return this.json(this.x.tg_feed());
  }
  // The next reading in order ({reading, method, warnings}) or null.
  popReading() {
    return this.json(this.x.tg_pop_reading());
  }
  // Files the last popped reading: {record, line}.
  file(filing) {
    this.input(0, JSON.stringify(filing));
    return this.json(this.x.tg_file_reading());
  }
  lastSeq() { return this.x.tg_last_seq(); }
  newestMs() { return this.x.tg_newest_ms(); }
  resumeAfter(seq) { this.x.tg_resume_after(seq); }
  restart() { this.x.tg_restart(); }
  hasGap() { return this.x.tg_has_gap() === 1; }
  historyRequested() { return this.x.tg_history_requested(); }
  historyEnded(afterSeq, deviceLast) {
    return this.json(this.x.tg_history_ended(afterSeq, deviceLast));
  }
  resetDecoder() { this.x.tg_reset_decoder(); }

  // ---- the field log --------------------------------------------------------------------
  // A record ({type: "plot", plot_id, started, note}) as its journal line.
  encodeRecord(record) {
    this.input(0, JSON.stringify(record));
    return this.text(this.x.tg_encode_record());
  }
  // A field log's bytes → {records, lines, findings} or {error}.
  importLog(bytes) {
    this.input(0, bytes);
    return this.json(this.x.tg_import());
  }
  // What `tangent log export --format csv|tsv|json [--plot-id ID]` writes for this log.
  exportLog(logText, format, plotId = "") {
    this.input(0, logText);
    this.input(1, plotId);
    return this.text(this.x.tg_export(["csv", "tsv", "json"].indexOf(format)));
  }
  // {tally: {species: [...], total}, trees: [the reading that counts per tree]}.
  tally(logText, plotId) {
    this.input(0, logText);
    this.input(1, plotId);
    return this.json(this.x.tg_tally());
  }
}
