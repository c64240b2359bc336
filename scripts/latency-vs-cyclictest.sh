#!/usr/bin/env bash
# Wake-up latency of edmd's real-time loop against cyclictest (Debian rt-tests), measured
# back to back at the same period and SCHED_FIFO priority on this machine.
#
#   scripts/latency-vs-cyclictest.sh [TICK_US] [PRIORITY] [SECONDS]     (defaults 50 80 20)
#
# edmd runs tests/data/runtime-path.nc in real time (output null, gap none) with its feed set
# so the job lasts about SECONDS; cyclictest then runs for the same time with one thread at
# the same interval and priority, memory locked (-m), with a 1 µs histogram from which p99 is
# computed the same way as edmd's (the upper edge of the bucket holding the 99th percentile).
# Needs root or CAP_SYS_NICE for SCHED_FIFO; without it both run unprivileged (and say so).
set -euo pipefail
cd "$(dirname "$0")/.."
tick_us=${1:-50}
prio=${2:-80}
seconds=${3:-20}
command -v cyclictest >/dev/null || { echo "needs cyclictest: apt-get install rt-tests" >&2; exit 1; }
cargo build --release --quiet
out=$(mktemp -d)
# 17.13 mm of path in `seconds` seconds.
feed=$(python3 -c "print(17.1327 / $seconds * 60)")
./target/release/edmd run tests/data/runtime-path.nc --summary "$out/edmd.json" \
  --set fine.virtual_time=false --set fine.tick_us="$tick_us" --set fine.rt_priority="$prio" \
  --set fine.lock_memory=true --set output.kind=null --set gap.kind=none \
  --set servo.normal_feed_mm_per_min="$feed" >"$out/edmd.txt" 2>"$out/edmd.err" || true
cyclictest -m -t1 -p "$prio" -i "$tick_us" -D "${seconds}s" -q -h 2000 >"$out/cyclictest.txt" 2>&1 || true
python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
e = json.load(open(f"{out}/edmd.json"))
lat = e["latency_us"]
counts = {}
overflow = None
for line in open(f"{out}/cyclictest.txt"):
    if line.startswith("#"):
        if "Max Latencies" in line:
            maxv = int(line.split(":")[1].split()[0])
        if "Histogram Overflows" in line:
            overflow = int(line.split(":")[1].split()[0])
        continue
    parts = line.split()
    if len(parts) == 2 and parts[0].isdigit():
        counts[int(parts[0])] = int(parts[1])
total = sum(counts.values()) + (overflow or 0)
def q(frac):
    rank, seen = frac * total, 0
    for us in sorted(counts):
        seen += counts[us]
        if seen >= rank:
            return us + 1  # bucket [us, us+1) -> upper edge, like edmd
    return float("inf")
print(f"edmd       : {lat['samples']} ticks  p50 {lat['p50_us']:.1f} µs  p99 {lat['p99_us']:.1f} µs  max {lat['max_us']:.1f} µs  overruns {e['overruns']}")
print(f"cyclictest : {total} loops  p50 {q(0.5):.1f} µs  p99 {q(0.99):.1f} µs  max {maxv} µs")
print(f"p99 ratio edmd/cyclictest: {lat['p99_us'] / q(0.99):.2f}")
for r in e["rt_refused"]:
    print("edmd warning:", r)
PY
rm -rf "$out"
