#!/usr/bin/env bash
# The turn-back as the pulse log shows it (BENCHMARKS.md, "The turn-back"): a straight cut along
# X at F3, F60 and F600 on the binary's built-in configuration (1 µm steps, 50 µs ticks,
# virtual time), with the servo's normal and open feeds above F (so F is the cutting speed)
# and `servo.retract_feed_mm_per_min = 120`.
# A scripted short (gap.kind = "script") starts once the cut is 2.5 mm long (tick 2.5 mm / F)
# and lasts 500 ms, then 2 ms.
# Per run it prints:
#   first back   ticks from the short's first tick to the first backward step
#   overrun      how far (µm) the electrode went on into the short before it turned back
#   back-off     the backward speed (mm/min), from the second backward step to the last
#   backed       how far (µm) it backed off in all
#   regain       ms from the gap clearing to the electrode back where the short began
#   end          the final X (µm) against the program's 5000
#
#   scripts/turn-back.sh [BINARY] [EXTRA --set ARGS...]     # default target/release/edmd
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
bin="$(realpath "${1:-$repo/target/release/edmd}")"
shift || true
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
for f in 3 60 600; do
  at=$((3000000 / f))
  for short in 10000 40; do
    printf 'G21 G90\nG1 X5 F%s\nM2\n' "$f" >prog.ngc
    printf '0 normal\n%s short\n%s normal\n' "$at" "$((at + short))" >gap.txt
    "$bin" run prog.ngc \
      --set gap.kind='"script"' --set gap.script='"gap.txt"' \
      --set output.kind='"file"' --set output.path='"pulses.csv"' \
      --set servo.normal_feed_mm_per_min=1000 --set servo.open_feed_mm_per_min=1000 \
      --set servo.retract_feed_mm_per_min=120 --set servo.max_short_s=0 \
      "$@" >run.log 2>&1 || { cat run.log >&2; exit 1; }
    python3 - "$f" "$at" "$short" pulses.csv <<'PY'
import sys
feed, short_at, short_ticks, path = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
tick_s, step_um = 50e-6, 1.0
clear_at = short_at + short_ticks
x, pos, back = 0, [], []  # (tick, x after the tick)
for line in open(path):
    if line.startswith("#") or line.startswith("tick"):
        continue
    r = line.strip().split(",")
    t, dx = int(r[0]), int(r[1])
    if dx:
        x += dx
        pos.append((t, x))
        if dx < 0:
            back.append(t)
x_at = lambda t: max([p for k, p in pos if k < t], default=0)
x_short = x_at(short_at)
first = back[0] - short_at if back else None
turned = back[0] if back else clear_at
overrun = max([x_short] + [p for k, p in pos if short_at <= k <= turned]) - x_short
lowest_k, lowest = min(((k, p) for k, p in pos if k >= turned), key=lambda kp: (kp[1], kp[0]))
backed = (x_short + overrun - lowest) if back else 0
speed = (len(back) - 1) * step_um / 1000 / ((back[-1] - back[0]) * tick_s) * 60 if len(back) > 2 else 0.0
regain = next((k for k, p in pos if k >= max(clear_at, lowest_k) and p >= x_short), None)
regain_ms = f"{(regain - clear_at) * tick_s * 1000:8.2f}" if back and regain is not None else ("   never" if back else "       -")
short_ms = short_ticks * tick_s * 1000
print(f"F{feed:<4} short {short_ms:6.0f} ms: first back {first if first is not None else 'none':>5} ticks, "
      f"overrun {overrun:3d} µm, back-off {speed:7.1f} mm/min, backed {backed:4d} µm, "
      f"regain {regain_ms} ms, end {x} µm")
PY
  done
done
