// Offline: the app's files are kept on first visit and served from the cache, so the page
// opens in the forest without a network. CACHE is replaced by app/build.sh with a hash of
// the files, so a new build replaces the old cache.
const CACHE = "tangent-app-BUILD";
const FILES = ["./", "index.html", "style.css", "app.js", "core.js", "link.js", "store.js", "tangent.wasm", "manifest.webmanifest", "icon.svg"];

self.addEventListener("install", (e) => {
  e.waitUntil(caches.open(CACHE).then((c) => c.addAll(FILES)).then(() => self.skipWaiting()));
});

self.addEventListener("activate", (e) => {
  e.waitUntil(
    caches.keys()
      .then((keys) => Promise.all(keys.filter((k) => k !== CACHE).map((k) => caches.delete(k))))
      .then(() => self.clients.claim()),
  );
});

self.addEventListener("fetch", (e) => {
  const url = new URL(e.request.url);
  if (e.request.method !== "GET" || url.origin !== location.origin || url.pathname.endsWith("/bridge")) return;
  e.respondWith(caches.match(e.request, { ignoreSearch: true }).then((hit) => hit || fetch(e.request)));
});
