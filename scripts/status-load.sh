#!/usr/bin/env bash
# The tick under a load of status readers (BENCHMARKS.md, "The tick first under load"):
# `edmd serve` with the web side on loopback and the shipped real-time settings (SCHED_FIFO 80,
# mlockall: run as root, or with the unit's limits) cuts a long program in real time to the
# null output; the counters are read, then `wrk` polls GET /api/status with CLIENTS
# connections for SECONDS, and the counters are read again. It prints, for the same job, the
# ticks that ended after their next deadline without the load and under it, and the status
# answers a second.
#
#   scripts/status-load.sh [BINARY] [TICK_US] [CLIENTS] [SECONDS] [SETTING=VALUE...]
#       defaults: target/release/edmd 200 50 10; needs Debian's wrk. The configuration is the
#       working directory's config/edmd.toml (run it from the checkout BINARY was built from);
#       settings after SECONDS are passed on as --set.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
bin="$(realpath "${1:-$repo/target/release/edmd}")"
tick="${2:-200}"
clients="${3:-50}"
seconds="${4:-10}"
extra=()
for set in "${@:5}"; do extra+=(--set "$set"); done
work="$(mktemp -d)"
trap 'kill "$daemon" 2>/dev/null || true; wait 2>/dev/null || true; rm -rf "$work"' EXIT
mkdir -p "$work/programs"
{
  printf 'G21 G90\n'
  for leg in $(seq 1 20); do printf 'G1 X10 Y0 F120\nG1 X0 Y0\n'; done
  printf 'M2\n'
} >"$work/programs/long.ngc"
"$bin" serve \
  --set daemon.socket="\"$work/edmd.sock\"" --set daemon.program_dir="\"$work/programs\"" \
  --set daemon.state_dir="\"$work/state\"" --set daemon.http='"127.0.0.1:18317"' \
  --set daemon.http_token_file="\"$work/token\"" --set fine.virtual_time=false \
  --set fine.tick_us="$tick" --set gap.kind='"none"' --set output.kind='"null"' \
  --set homing.required=false --set log.format='"plain"' "${extra[@]}" 2>"$work/serve.log" &
daemon=$!
for _ in $(seq 1 100); do [ -S "$work/edmd.sock" ] && break; sleep 0.1; done
"$bin" ctl --socket "$work/edmd.sock" run long.ngc >/dev/null
sleep 2
counters() {
  "$bin" ctl --json --socket "$work/edmd.sock" status |
    python3 -c 'import json,sys; c=json.load(sys.stdin)["status"]["counters"]; print(c["ticks"], c["overruns"])'
}
read -r t0 o0 < <(counters)
sleep "$seconds"
read -r t1 o1 < <(counters)
rps=$(wrk -t 2 -c "$clients" -d "${seconds}s" http://127.0.0.1:18317/api/status |
  awk '/Requests\/sec/ {print $2}')
read -r t2 o2 < <(counters)
python3 - "$t0" "$o0" "$t1" "$o1" "$t2" "$o2" "$rps" "$tick" "$clients" <<'PY'
import sys
t0, o0, t1, o1, t2, o2 = map(int, sys.argv[1:7])
rps, tick, clients = sys.argv[7:]
quiet = 100 * (o1 - o0) / max(1, t1 - t0)
loaded = 100 * (o2 - o1) / max(1, t2 - t1)
print(f"tick {tick} us: overruns {quiet:.3f} % without the load, {loaded:.3f} % under "
      f"{clients} clients ({rps} status answers/s)")
PY
grep -i "refused" "$work/serve.log" | head -3 || true
