#!/usr/bin/env bash
# The field app's browser tests (docs/field-app.md): installs what they need when missing —
# Debian's chromium (apt, as root) and playwright-core (npm ci) — builds the app, the
# `tangent` binary (as the workspace's tests do) and the emulated firmware, then runs app/e2e/*.test.mjs with node's test
# runner. Exit 77 (skipped, with the reason printed) when chromium, node/npm or QEMU
# cannot be had here.
#   bash app/e2e/run.sh            TANGENT_SCREENSHOTS=docs/field-app bash app/e2e/run.sh
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
cd "$root"

skip() { echo "SKIPPED: $*"; exit 77; }

apt_install() {
  [ "$(id -u)" = 0 ] || return 1
  command -v apt-get >/dev/null || return 1
  echo "installing $* (apt)"
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$@") >/tmp/tangent-app-apt.log 2>&1 \
    || { tail -5 /tmp/tangent-app-apt.log; return 1; }
}

chromium=${CHROMIUM:-/usr/bin/chromium}
[ -x "$chromium" ] || apt_install chromium || skip "chromium is not installed and could not be (apt-get install chromium, as root)"
command -v npm >/dev/null || apt_install nodejs npm || skip "node/npm are not installed and could not be (apt-get install nodejs npm)"
command -v qemu-system-arm >/dev/null || apt_install qemu-system-arm || skip "qemu-system-arm is not installed and could not be"
node_major=$(node -p 'process.versions.node.split(".")[0]')
[ "$node_major" -ge 18 ] || skip "node $node_major is too old (18 or later needed)"

if [ ! -f "$here/node_modules/playwright-core/package.json" ]; then
  (cd "$here" && npm ci --no-audit --no-fund --loglevel=error) || skip "npm ci could not install playwright-core"
fi

set -e
bash app/build.sh
# The `tangent` binary exactly as the workspace's tests build it (same command, so the same
# features — dev-dependencies change some — and profile): in CI, after `cargo test
# --workspace --release`, nothing is compiled again.
cargo test --workspace --release --no-run
cargo firmware-qemu
cd "$here"
exec node --test --test-concurrency=1 --test-reporter=spec
