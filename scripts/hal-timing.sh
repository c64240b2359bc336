#!/usr/bin/env bash
# Timing of edmd on LinuxCNC's HAL (docs/hal.md, BENCHMARKS.md): the shipped simulated machine
# (config/hal/sim.hal) with HAL's `sampler` in the 25 µs base thread recording edmd.gap.short,
# edmd.estop-ok-in, edmd.enable-out, stepgen.0.counts and edmd.axis.x.pos-cmd; `halsampler`
# streams them out. Per run: a 200 ms short on edmd.gap.short during a cut at F120, then the
# E-stop input. Prints, per run, from the short to edmd's first backward pos-cmd and to
# stepgen's first backward step, and from the E-stop input to enable-out false.
#
#   sudo scripts/hal-timing.sh [BINARY_DIR] [RUNS]     # default target/release, 5 runs
# Needs Debian's linuxcnc-uspace; runs as root (rtapi_app drops to RTAPI_UID=nobody).
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
bin_dir="$(realpath "${1:-$repo/target/release}")"
runs="${2:-5}"
work="$(mktemp -d)"
trap 'rm -rf "$work"; halrun -U >/dev/null 2>&1 || true' EXIT
mkdir -p "$work/programs" "$work/home" "$work/config/hal"
chmod 755 "$work"
chown nobody "$work/home"
sed "s|/tmp/edmd-hal|$work|" "$repo/config/hal/sim.toml" >"$work/config/hal/sim.toml"
printf 'G21 G90\nG1 X20 F120\nM2\n' >"$work/programs/long.ngc"
printf '#!/bin/sh\nhalsampler -t >"%s/samples.txt" 2>/dev/null &\nsleep 0.2\n' "$work" >"$work/sampler.sh"
export RTAPI_UID="$(id -u nobody)" HOME="$work/home" PATH="$bin_dir:$PATH"
cd "$work"
for run in $(seq 1 "$runs"); do
  rm -f checkpoint.json machine-state.json samples.txt
  {
    echo "loadrt sampler depth=40000 cfg=bbbsf"
    echo "addf sampler.0 base-thread"
    echo "net s-short edmd.gap.short => sampler.0.pin.0"
    echo "net s-estop edmd.estop-ok-in => sampler.0.pin.1"
    echo "sets s-estop true"
    echo "net drives-on => sampler.0.pin.2"
    echo "net s-count stepgen.0.counts => sampler.0.pin.3"
    echo "net x-pos-cmd => sampler.0.pin.4"
    echo "loadusr -w sh $work/sampler.sh"
    echo "loadusr -w edmd ctl --socket $work/edmd.sock run long.ngc"
    echo "loadusr -w sleep 1.5"
    echo "sets s-short true"
    echo "loadusr -w sleep 0.2"
    echo "sets s-short false"
    echo "loadusr -w sleep 1"
    echo "sets s-estop false"
    echo "loadusr -w sleep 0.3"
    echo "exit"
  } | timeout 120 halrun -I -f "$repo/config/hal/sim.hal" >halrun.log 2>&1 || true
  [ -s samples.txt ] || { grep -v fallback halrun.log >&2; exit 1; }
  python3 - "$run" "$work/samples.txt" <<'PY'
import sys
run, path = sys.argv[1], sys.argv[2]
rows = []
for line in open(path):
    r = line.split()
    if len(r) == 6:
        rows.append((int(r[0]), int(r[1]), int(r[2]), int(r[3]), int(r[4]), float(r[5])))
base_us, servo = 25.0, 40.0  # sim.hal: base thread 25 µs, servo thread 1 ms

def first(pred, start=0):
    return next((k for k in range(start, len(rows)) if pred(rows[k])), None)

short = first(lambda r: r[1] == 1)
window = range(short, min(len(rows), short + 20000))
k_cmd = max(window, key=lambda k: rows[k][5])
cmd_back = first(lambda r: r[5] < rows[k_cmd][5] - 1e-9, k_cmd)
k_cnt = max(window, key=lambda k: rows[k][4])
cnt_back = first(lambda r: r[4] < rows[k_cnt][4], k_cnt)
estop = first(lambda r: r[2] == 0, short + 1)
off = first(lambda r: r[3] == 0, estop)
ms = lambda n: n * base_us / 1000
print(f"run {run}: short -> pos-cmd back {ms(cmd_back - short):.2f} ms, stepgen back "
      f"{ms(cnt_back - short):.2f} ms ({(cnt_back - short) / servo:.1f} servo periods; "
      f"{(cnt_back - cmd_back) / servo:.1f} after pos-cmd), overrun {rows[k_cnt][4] - rows[short][4]} steps; "
      f"E-stop -> enable-out false {(off - estop) * base_us:.0f} us ({(off - estop) / servo:.2f} servo periods)")
PY
done
