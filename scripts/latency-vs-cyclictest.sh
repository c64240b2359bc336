#!/usr/bin/env bash
# Wake-up latency and CPU per tick of edmd's real-time loop against cyclictest (Debian
# rt-tests), measured back to back at the same periods and SCHED_FIFO priority on this machine.
#
#   scripts/latency-vs-cyclictest.sh [TICKS_US] [PRIORITY] [SECONDS]   (defaults 25,50,100 80 10)
#
# TICKS_US is a comma-separated list of periods; each is measured in turn, edmd then
# cyclictest, and all land in one table.
# `edmd latency` runs the real consumer loop (fine interpolator stepping round an endless
# square at the servo's normal feed, output null, gap normal) for SECONDS with memory locked
# and /dev/cpu_dma_latency held at 0; cyclictest then runs right after for the same time with
# one thread at the same interval and priority, memory locked (-m). Both print a 1 µs
# histogram in cyclictest's -h layout, and both are read by the same code below (p50 and p99
# are the upper edge of the bucket holding that quantile; overflows count beyond 2 ms). CPU
# per loop is the process's user + system time (`/usr/bin/time`) over its loops: what a tick
# costs the machine, wake-up and sleep included.
# Needs root or CAP_SYS_NICE for SCHED_FIFO; without it both run unprivileged (and say so).
set -euo pipefail
cd "$(dirname "$0")/.."
ticks=${1:-25,50,100}
prio=${2:-80}
seconds=${3:-10}
command -v cyclictest >/dev/null || { echo "needs cyclictest: apt-get install rt-tests" >&2; exit 1; }
cargo build --release --quiet
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for tick_us in ${ticks//,/ }; do
  /usr/bin/time -f "%U %S" -o "$out/edmd-$tick_us.cpu" ./target/release/edmd latency \
    --tick-us "$tick_us" --priority "$prio" --seconds "$seconds" \
    --set fine.lock_memory=true --histogram "$out/edmd-$tick_us.txt" >/dev/null
  /usr/bin/time -f "%U %S" -o "$out/cyclictest-$tick_us.cpu" cyclictest -m -t1 -p "$prio" \
    -i "$tick_us" -D "${seconds}s" -q -h 2000 >"$out/cyclictest-$tick_us.txt" 2>&1 || true
done
python3 - "$out" "$(nproc)" "$(uname -r)" "$ticks" "$(cyclictest --help 2>&1 | head -1)" <<'PY'
import sys
out, cpus, kernel, ticks, version = sys.argv[1:6]

def read(path):
    """A cyclictest -h histogram: {µs: count}, overflows, max µs, header comments."""
    counts, overflow, maxv, notes = {}, 0, None, []
    for line in open(path):
        if line.startswith("#"):
            if "Histogram Overflows" in line:
                overflow = int(line.split(":")[1].split()[0])
            elif "Max Latencies" in line:
                maxv = int(line.split(":")[1].split()[0])
            elif line.startswith("# edmd") or line.startswith("# overruns"):
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

def cpu_seconds(path):
    # /usr/bin/time may put a "Command exited with non-zero status" line first.
    user, system = open(path).read().split()[-2:]
    return float(user) + float(system)

print(f"machine: {cpus} CPUs, Linux {kernel}; {version.strip()}")
print(f"{'tick':>6} {'':11} {'loops':>8} {'p50 µs':>7} {'p99 µs':>7} {'max µs':>7} {'>2 ms':>6} {'CPU µs/loop':>12}")
ratios = []
for tick in ticks.split(","):
    rows = {}
    for name in ("edmd", "cyclictest"):
        counts, overflow, maxv, notes = read(f"{out}/{name}-{tick}.txt")
        total = sum(counts.values()) + overflow
        cpu = cpu_seconds(f"{out}/{name}-{tick}.cpu") * 1e6 / max(total, 1)
        rows[name] = (total, quantile(counts, overflow, 0.5), quantile(counts, overflow, 0.99), maxv, overflow, cpu)
        for n in notes:
            print(f"  {tick} µs {name}: {n}")
    for name, (total, p50, p99, maxv, overflow, cpu) in rows.items():
        print(f"{tick:>4}µs {name:11} {total:8} {p50:7} {p99:7} {maxv:7} {overflow:6} {cpu:12.2f}")
    e, c = rows["edmd"], rows["cyclictest"]
    ratios.append((tick, e[2] / c[2], e[5] / c[5]))
for tick, p99, cpu in ratios:
    print(f"{tick} µs: p99 ratio edmd/cyclictest {p99:.2f}, CPU per loop ratio {cpu:.2f}")
PY
