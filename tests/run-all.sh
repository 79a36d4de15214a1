#!/usr/bin/env bash
# Runs every test of Tangent from a fresh clone and prints one summary line:
#   "tests: N passed, N failed, N skipped"
# Each step's start (clock time) and duration are printed, and the durations again before the
# summary (CI's budget: 20 min on 2 cores from a fresh clone).
# It installs what the tests need first (the thumbv7em target through rustup, which reads
# rust-toolchain.toml; qemu-system-arm through apt when running as root).
set -uo pipefail
cd "$(dirname "$0")/.."

passed=0
failed=0
skipped=0
failed_steps=()
timings=()
log_dir=$(mktemp -d)
started=$SECONDS

note() { printf '\n=== %s [%s] ===\n' "$*" "$(date +%T)"; step_started=$SECONDS; }
# timed NAME STATUS: the step's duration, printed and kept for the summary.
timed() {
  local took=$((SECONDS - step_started))
  printf -- '--- %s: %d s (exit %s)\n' "$1" "$took" "$2"
  timings+=("$(printf '%-16s %4d s' "$1" "$took")")
}

# --- prerequisites -----------------------------------------------------------------
note "prerequisites"
rustup show active-toolchain >/dev/null 2>&1 || true   # installs the pinned toolchain if missing
rustup target add thumbv7em-none-eabihf >/dev/null 2>&1 || echo "warning: could not add the thumbv7em-none-eabihf target"
if ! command -v qemu-system-arm >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ]; then
    echo "installing qemu-system-arm (apt)"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq qemu-system-arm) >"$log_dir/apt.log" 2>&1 \
      || { echo "warning: apt-get install qemu-system-arm failed"; tail -5 "$log_dir/apt.log"; }
  else
    echo "warning: qemu-system-arm missing and not root: emulated-firmware tests will fail"
  fi
fi
command -v qemu-system-arm >/dev/null 2>&1 && qemu-system-arm --version | head -1
timed prerequisites 0

# run_cargo_tests NAME CMD... : runs a cargo test command and adds its counts.
run_cargo_tests() {
  local name=$1; shift
  note "$name: $*"
  local out="$log_dir/$name.log"
  "$@" 2>&1 | tee "$out"
  local status=${PIPESTATUS[0]}
  timed "$name" "$status"
  local p f
  read -r p f < <(awk '/^test result:/ { for (i = 1; i <= NF; i++) { if ($i ~ /^passed;?$/) p += $(i-1); if ($i ~ /^failed;?$/) f += $(i-1) } } END { print p + 0, f + 0 }' "$out")
  passed=$((passed + ${p:-0}))
  failed=$((failed + ${f:-0}))
  if [ "$status" -ne 0 ]; then
    failed_steps+=("$name")
    # A build failure runs no test: count the step itself as one failure.
    [ "${f:-0}" -eq 0 ] && failed=$((failed + 1))
  fi
}

# run_step NAME CMD... : a non-test step (a build); counts as one pass or one failure, or as
# one skip when the step exits 77 (it could not run here and printed why).
run_step() {
  local name=$1; shift
  note "$name: $*"
  "$@"
  local status=$?
  timed "$name" "$status"
  if [ "$status" -eq 0 ]; then passed=$((passed + 1))
  elif [ "$status" -eq 77 ]; then skipped=$((skipped + 1))
  else failed=$((failed + 1)); failed_steps+=("$name"); fi
}

# Firmware: release builds of both boards for the Cortex-M7 (the emulated board's ELF is also
# what the host's emulated-device tests run under QEMU), then its portable logic on the host.
run_step firmware-h743 cargo firmware
run_step firmware-qemu cargo firmware-qemu
run_cargo_tests firmware-logic bash -c 'cd firmware && cargo test --target x86_64-unknown-linux-gnu --no-default-features --lib'

# Host and core (including the corpus, the simulator, calibration on real images and the
# emulated device under QEMU), then the core again in single precision, as on the device.
run_cargo_tests host-and-core cargo test --workspace --release --no-fail-fast
run_cargo_tests core-f32 cargo test -p tangent-core --features f32 --release --no-fail-fast

# Fuzzing smoke test: every libFuzzer target for 5 s (docs/fuzzing.md). --ci installs nothing:
# without nightly + cargo-fuzz it prints why it skips (a cold install and build take ~9 min);
# `bash fuzz/run.sh` once installs them. With them, the first build takes ~6 min, later ones
# seconds; the runs take ~40 s.
run_step fuzz-smoke bash fuzz/run.sh 5 --ci

# The field app in headless Chromium against the emulated caliper (docs/field-app.md). Installs
# chromium (apt) and playwright-core (npm ci) when missing; exits 77 (skipped, reason printed)
# when they cannot be had. Each browser test counts; a build failure counts as one failure.
run_node_tests() {
  local name=$1; shift
  note "$name: $*"
  local out="$log_dir/$name.log"
  "$@" 2>&1 | tee "$out"
  local status=${PIPESTATUS[0]}
  timed "$name" "$status"
  if [ "$status" -eq 77 ]; then skipped=$((skipped + 1)); return; fi
  local p f
  p=$(awk '/^ℹ pass [0-9]+$/ { n = $3 } END { print n + 0 }' "$out")
  f=$(awk '/^ℹ fail [0-9]+$/ { n = $3 } END { print n + 0 }' "$out")
  passed=$((passed + p))
  failed=$((failed + f))
  if [ "$status" -ne 0 ]; then
    failed_steps+=("$name")
    [ "$f" -eq 0 ] && failed=$((failed + 1))
  fi
}
run_node_tests field-app bash app/e2e/run.sh

# --- summary -----------------------------------------------------------------------
echo
echo "time per step:"
printf '  %s\n' "${timings[@]}"
echo "  total            $((SECONDS - started)) s"
if [ ${#failed_steps[@]} -gt 0 ]; then
  echo "failed steps: ${failed_steps[*]}"
fi
echo "tests: $passed passed, $failed failed, $skipped skipped"
rm -rf "$log_dir"
[ "$failed" -eq 0 ]
