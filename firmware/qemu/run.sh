#!/usr/bin/env bash
# Runs the emulated Tangent firmware under QEMU (mps2-an500, Cortex-M7).
#
#   firmware/qemu/run.sh [--build] [--icount] [--serial SPEC] -- [--calib FILE] [--mode-store FILE] [--bench] [--accel FX,FY,FZ [--accel-noise SIGMA]] OFF.pgm ON.pgm [...]
#
#   --build        build the ELF first (release, --no-default-features --features qemu)
#   --icount       deterministic instruction counting: 1 ns of virtual time per instruction
#                  (the benchmark; the firmware's clock then counts instructions)
#   --serial SPEC  where the device's UART goes (QEMU -serial syntax): `stdio` (default;
#                  binary protocol on stdin/stdout), `pty` (QEMU prints the /dev/pts path,
#                  for `tangent --port`), `unix:PATH,server=on,wait=off`, `tcp::PORT,server=on`…
#
# The firmware's log (and --bench results) go to stderr through semihosting. Frame files
# are binary PGMs (8-bit, or 16-bit reduced to the top 8 bits); paths must not contain
# spaces. The calibration is a calibration record (docs/protocol.md); the mode store is the
# file of the mode log (docs/hardware.md, "The instrument mode"), created on the first SetMode.
# --accel fits the emulated ADXL355, sensing that specific force (sensor axes, m/s²; e.g.
# 0,-9.80665,0 for a level device) with the part's noise or --accel-noise (m/s² per sample).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
fw=$(dirname "$here")
elf="$fw/target/thumbv7em-none-eabihf/release/tangent-qemu"
build=0 icount=() serial=stdio
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build=1 ;;
    --icount) icount=(-icount shift=0) ;;
    --serial) serial=$2; shift ;;
    --) shift; break ;;
    *) break ;;
  esac
  shift
done
if [ "$build" = 1 ]; then
  cargo build --manifest-path "$fw/Cargo.toml" --release --no-default-features --features qemu --bin tangent-qemu >&2
fi
[ -f "$elf" ] || { echo "no $elf: run with --build (or cargo firmware-qemu at the repo root)" >&2; exit 2; }
command -v qemu-system-arm >/dev/null || { echo "qemu-system-arm not found (apt-get install qemu-system-arm)" >&2; exit 2; }
exec qemu-system-arm -M mps2-an500 -display none -monitor none -nodefaults -net none \
  "${icount[@]}" \
  -semihosting-config enable=on,target=native \
  -serial "$serial" \
  -kernel "$elf" -append "$*"
