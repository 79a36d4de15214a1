#!/usr/bin/env bash
# Runs every fuzz target for SECONDS each (default 10) and prints one line per target:
#   fuzz <target>: <execs> execs, <exec/s> exec/s, ok|CRASH
# exiting non-zero if any target crashed (the input is kept in fuzz/artifacts/<target>/).
#
#   bash fuzz/run.sh [SECONDS] [--ci] [--runs=N] [TARGET...]
#
# --runs=N runs each target for N executions instead of SECONDS (the long run of
# docs/fuzzing.md: --runs=10000000).
# From a fresh machine it installs what it needs: a nightly toolchain (rustup, minimal
# profile) and cargo-fuzz (crates.io, --locked). With --ci it installs nothing: if either is
# missing it says so and skips (a cold install plus the first build takes ~9 min; see
# docs/fuzzing.md). New inputs go to fuzz/target/corpus/<target>/; the checked-in seeds in
# fuzz/corpus/<target>/ are only read.
set -uo pipefail
cd "$(dirname "$0")"

seconds=10
ci=0
limit=()
targets=()
for arg in "$@"; do
  case $arg in
    --ci) ci=1 ;;
    --runs=*) limit=(-runs="${arg#--runs=}") ;;
    ''|*[!0-9]*) targets+=("$arg") ;;
    *) seconds=$arg ;;
  esac
done
[ ${#limit[@]} -eq 0 ] && limit=(-max_total_time="$seconds")

missing=()
rustup run nightly rustc --version >/dev/null 2>&1 || missing+=("the nightly toolchain")
cargo fuzz --version >/dev/null 2>&1 || missing+=("cargo-fuzz")
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$ci" = 1 ]; then
    echo "fuzz: SKIPPED — ${missing[*]} not installed; installing and building from cold takes" \
         "~9 min, beyond the CI step's budget. Run \`bash fuzz/run.sh\` once on this machine" \
         "to install them; CI then runs the targets."
    exit 77  # "skipped" for tests/run-all.sh: counted apart, never as a pass
  fi
  if ! rustup run nightly rustc --version >/dev/null 2>&1; then
    echo "installing the nightly toolchain (rustup, minimal profile)"
    rustup toolchain install nightly --profile minimal || exit 1
  fi
  if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "installing cargo-fuzz (crates.io)"
    cargo install cargo-fuzz --locked || exit 1
  fi
fi

# No sanitizer: the code is safe Rust, so AddressSanitizer finds nothing a panic would not,
# and without it the targets build faster and run ~2x faster. Debug assertions and overflow
# checks are on (-a): an overflow is a finding.
build_flags=(-s none -a)
[ ${#targets[@]} -eq 0 ] && mapfile -t targets < <(cargo +nightly fuzz list)
cargo +nightly fuzz build "${build_flags[@]}" || { echo "fuzz: build FAILED"; exit 1; }

status=0
for target in "${targets[@]}"; do
  work="target/corpus/$target"
  mkdir -p "$work" "artifacts/$target"
  log="target/fuzz-$target.log"
  cargo +nightly fuzz run "${build_flags[@]}" "$target" "$work" "corpus/$target" -- \
    "${limit[@]}" -print_final_stats=1 -rss_limit_mb=1024 -timeout=10 \
    >"$log" 2>&1
  result=$?
  execs=$(awk '/stat::number_of_executed_units:/ { print $2 }' "$log")
  rate=$(awk '/stat::average_exec_per_sec:/ { print $2 }' "$log")
  if [ "$result" -eq 0 ]; then
    verdict=ok
  else
    verdict=CRASH
    status=1
  fi
  echo "fuzz $target: ${execs:-?} execs, ${rate:-?} exec/s, $verdict"
  [ "$verdict" = CRASH ] && grep -m5 -E "panicked|ERROR|SUMMARY|Test unit written" "$log" | sed 's/^/  /'
done
exit $status
