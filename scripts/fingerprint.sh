#!/usr/bin/env bash
# Fingerprint of what edmd does on the papers' programs: SHA-256 of the pulse log of
# `edmd run` (output.kind = "file", default config otherwise: the simulated gap) and of every
# file `edmd plan` writes, with the measured fields of the summaries (wall time, segments/s,
# peak RSS) left out. Two builds that print the same fingerprint behave the same, byte for
# byte; a refactor must not change it.
#
#   scripts/fingerprint.sh [EDMD_BINARY]      # default: target/release/edmd
set -euo pipefail
cd "$(dirname "$0")/.."
bin="$(realpath "${1:-target/release/edmd}")"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
for program in programs/huang-table1-g38.nc programs/jin-table1-g06_2.nc; do
  name="$(basename "$program" .nc)"
  "$bin" run "$program" --set output.kind='"file"' --set output.path="\"$work/$name.pulses.csv\"" \
    >/dev/null 2>&1
  "$bin" plan "$program" --out "$work/plan-$name" -q >/dev/null 2>&1
  for f in "$work/plan-$name"/summary.json "$work/plan-$name"/summary.txt; do
    grep -v -e wall_time -e segments_per_second -e peak_rss -e 'wall time' -e 'peak RSS' "$f" \
      >"$f.masked"
    rm "$f"
  done
done
(cd "$work" && sha256sum ./*.pulses.csv plan-*/* | sort -k2)
