#!/usr/bin/env bash
# Wake-up latency of edmd's real-time loop against cyclictest (Debian rt-tests), measured
# back to back at the same period and SCHED_FIFO priority on this machine.
#
#   scripts/latency-vs-cyclictest.sh [TICK_US] [PRIORITY] [SECONDS]     (defaults 50 80 20)
#
# `edmd latency` runs the real consumer loop (fine interpolator stepping round an endless
# square at the servo's normal feed, output null, gap normal) for SECONDS with memory locked
# and /dev/cpu_dma_latency held at 0; cyclictest then runs right after for the same time with
# one thread at the same interval and priority, memory locked (-m). Both print a 1 µs
# histogram in cyclictest's -h layout, and both are read by the same code below (p50 and p99
# are the upper edge of the bucket holding that quantile; overflows count beyond 2 ms).
# Needs root or CAP_SYS_NICE for SCHED_FIFO; without it both run unprivileged (and say so).
set -euo pipefail
cd "$(dirname "$0")/.."
tick_us=${1:-50}
prio=${2:-80}
seconds=${3:-20}
command -v cyclictest >/dev/null || { echo "needs cyclictest: apt-get install rt-tests" >&2; exit 1; }
cargo build --release --quiet
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
./target/release/edmd latency --tick-us "$tick_us" --priority "$prio" --seconds "$seconds" \
  --set fine.lock_memory=true --histogram "$out/edmd.txt" >/dev/null
cyclictest -m -t1 -p "$prio" -i "$tick_us" -D "${seconds}s" -q -h 2000 >"$out/cyclictest.txt" 2>&1 || true
python3 - "$out" "$(nproc)" "$(uname -r)" <<'PY'
import sys
out, cpus, kernel = sys.argv[1], sys.argv[2], sys.argv[3]

def read(path):
    """A cyclictest -h histogram: {µs: count}, overflows, max µs, header comments."""
    counts, overflow, maxv, notes = {}, 0, None, []
    for line in open(path):
        if line.startswith("#"):
            if "Histogram Overflows" in line:
                overflow = int(line.split(":")[1].split()[0])
            elif "Max Latencies" in line:
                maxv = int(line.split(":")[1].split()[0])
            elif line.startswith("# edmd") or line.startswith("# p50") or line.startswith("# overruns"):
                notes.append(line[2:].rstrip())
            continue
        parts = line.split()
        if len(parts) == 2 and parts[0].isdigit():
            counts[int(parts[0])] = int(parts[1])
    return counts, overflow, maxv, notes

def quantile(counts, overflow, frac):
    total = sum(counts.values()) + overflow
    rank, seen = frac * total, 0
    for us in sorted(counts):
        seen += counts[us]
        if seen >= rank:
            return us + 1  # bucket [us, us+1) -> its upper edge
    return float("inf")

rows = {}
for name in ("edmd", "cyclictest"):
    counts, overflow, maxv, notes = read(f"{out}/{name}.txt")
    total = sum(counts.values()) + overflow
    rows[name] = (total, quantile(counts, overflow, 0.5), quantile(counts, overflow, 0.99), maxv, overflow)
    for n in notes:
        print(f"{name}: {n}")
print(f"machine: {cpus} CPUs, Linux {kernel}")
print(f"{'':11} {'loops':>8} {'p50 µs':>7} {'p99 µs':>7} {'max µs':>7} {'>2 ms':>6}")
for name, (total, p50, p99, maxv, overflow) in rows.items():
    print(f"{name:11} {total:8} {p50:7} {p99:7} {maxv:7} {overflow:6}")
print(f"p99 ratio edmd/cyclictest: {rows['edmd'][2] / rows['cyclictest'][2]:.2f}")
PY
