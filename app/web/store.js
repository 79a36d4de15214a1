// The app's storage: IndexedDB, written before anything is shown. A transaction's
// `complete` event is IndexedDB's durability point ("strict" where the browser offers it),
// the browser's equivalent of `tangent listen`'s write + fsync.
//
// Stores:
//   lines: the field log's records as journal lines (made by the core), in order
//          {id (auto), line, kind: "plot"|"tree", plot_id, tree_id?, device_id?, seq?, device_time_ms?}
//   meta:  small state {key, value}: current plot, next tree, species, settings, and per
//          device the last reading stored ("device:<id>" → {seq, device_time_ms}).

const DB = "tangent-field";

function req(r) {
  return new Promise((resolve, reject) => {
    r.onsuccess = () => resolve(r.result);
    r.onerror = () => reject(r.error);
  });
}

export class Store {
  static async open() {
    const open = indexedDB.open(DB, 1);
    open.onupgradeneeded = () => {
      const db = open.result;
      const lines = db.createObjectStore("lines", { keyPath: "id", autoIncrement: true });
      lines.createIndex("reading", ["device_id", "seq", "device_time_ms"]);
      db.createObjectStore("meta", { keyPath: "key" });
    };
    const db = await req(open);
    // Ask the browser not to evict the day's work under storage pressure.
    if (navigator.storage && navigator.storage.persist) navigator.storage.persist().catch(() => {});
    return new Store(db);
  }

  constructor(db) { this.db = db; }

  tx(stores, mode) {
    return this.db.transaction(stores, mode, { durability: "strict" });
  }

  done(t) {
    return new Promise((resolve, reject) => {
      t.oncomplete = () => resolve();
      t.onerror = () => reject(t.error);
      t.onabort = () => reject(t.error || new Error("transaction aborted"));
    });
  }

  // Appends entries (and meta updates) in one transaction; resolves once durable.
  async append(entries, meta = {}) {
    const t = this.tx(["lines", "meta"], "readwrite");
    const lines = t.objectStore("lines");
    const ids = entries.map((e) => req(lines.add(e)));
    for (const [key, value] of Object.entries(meta)) t.objectStore("meta").put({ key, value });
    await this.done(t);
    return Promise.all(ids);
  }

  // Whether the reading (device, seq, device time) is stored already.
  async has(deviceId, seq, deviceTimeMs) {
    const t = this.tx(["lines"], "readonly");
    const n = await req(t.objectStore("lines").index("reading").count([deviceId, seq, deviceTimeMs]));
    return n > 0;
  }

  async all() {
    const t = this.tx(["lines"], "readonly");
    return req(t.objectStore("lines").getAll());
  }

  async remove(id, meta = {}) {
    const t = this.tx(["lines", "meta"], "readwrite");
    t.objectStore("lines").delete(id);
    for (const [key, value] of Object.entries(meta)) t.objectStore("meta").put({ key, value });
    await this.done(t);
  }

  async get(key, fallback) {
    const t = this.tx(["meta"], "readonly");
    const r = await req(t.objectStore("meta").get(key));
    return r === undefined ? fallback : r.value;
  }

  async set(meta) {
    const t = this.tx(["meta"], "readwrite");
    for (const [key, value] of Object.entries(meta)) t.objectStore("meta").put({ key, value });
    await this.done(t);
  }
}
