#!/usr/bin/env bash
# Builds the field app into app/dist/: the WebAssembly core (app/wasm, tangent-core and
# tangent-field for wasm32-unknown-unknown) and the page's plain files (app/web).
#   bash app/build.sh          then: cargo run --release -p tangent-host -- app
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
rustup target add wasm32-unknown-unknown >/dev/null 2>&1 || true
cargo build --release -p tangent-app-wasm --target wasm32-unknown-unknown
dist=app/dist
rm -rf "$dist.tmp" && mkdir -p "$dist.tmp"
cp app/web/*.html app/web/*.js app/web/*.css app/web/*.webmanifest app/web/*.svg "$dist.tmp/"
cp target/wasm32-unknown-unknown/release/tangent_app_wasm.wasm "$dist.tmp/tangent.wasm"
# A new build gets a new offline cache (sw.js), named by the files' hash.
hash=$(cat "$dist.tmp"/* | sha256sum | cut -c1-12)
sed -i "s/tangent-app-BUILD/tangent-app-$hash/" "$dist.tmp/sw.js"
rm -rf "$dist" && mv "$dist.tmp" "$dist"
echo "built $dist ($(du -sk "$dist" | cut -f1) KiB; tangent.wasm $(($(stat -c %s "$dist/tangent.wasm") / 1024)) KiB)"
