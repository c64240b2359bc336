#!/usr/bin/env bash
# Fingerprint of what edmd does on the papers' programs: SHA-256 of the pulse log of
# `edmd run` (output.kind = "file", default config otherwise: the simulated gap) and of every
# file `edmd plan` writes, with the measured fields of the summaries (wall time, segments/s,
# peak RSS) left out; then of the job's path on wire and sinker jobs (the pulse logs of a die
# and a punch whole, in passes, with a tab; runs from a line by path and direct; a sinker's
# orbit; a tapered die with an arc and a NURBS corner; `check` on each kind). Two builds that
# print the same fingerprint behave the same, byte for byte; a refactor must not change it.
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

# The job's path: wire offset, passes, tabs, runs from a line, orbit, taper.
printf '(die)\nG21 G90 G17\nG41 D1\nG1 X0 Y-2 F600\nG1 X2 Y-2\nG1 X2 Y2\nG1 X-2 Y2\nG1 X-2 Y-2\nG1 X0 Y-2\nG40 G1 X0 Y0\nM2\n' \
  >"$work/die.ngc"
printf '(punch)\nG21 G90 G17\nG42 D1\nG1 X0 Y2 F600\nG1 X2 Y2\nG1 X2 Y6\nG1 X-2 Y6\nG1 X-2 Y2\nG1 X0 Y2\nG40 G1 X0 Y0\nM2\n' \
  >"$work/punch.ngc"
printf '(tapered die)\nG21 G90 G17\nG52 A3\nG41 D1\nG1 X0 Y-5 F300\nG1 X5 Y-5\nG5.2 X10 Y-5 P0.7071067811865476 L3\nX10 Y0 P1\nG5.3\nG3 X5 Y5 I-5 J0\nG1 X-5 Y5\nG1 X-5 Y-5\nG1 X0 Y-5\nG40 G50 G1 X0 Y0\nM2\n' \
  >"$work/taper.ngc"
cat >"$work/table.toml" <<'TOML'
[compensation]
d_mm = [0.0, 0.2]

[generator]
condition = [
  { number = 1, on_us = 1.0, off_us = 12.0, current_a = 1.0, v_ref = 35.0, feed_mm_per_min = 600.0 },
  { number = 3, on_us = 4.0, off_us = 8.0, current_a = 5.0, v_ref = 25.0, feed_mm_per_min = 600.0 } ]

[wire]
pass = [
  { offset_mm = 0.2, condition = 3 },
  { offset_mm = 0.15, condition = 1, reverse = true },
  { offset_mm = 0.12, condition = 1 } ]
TOML
sed 's/^\[wire\]$/[wire]\ntab_mm = 1.5/' "$work/table.toml" >"$work/tab.toml"
printf '[machine]\naxes = ["X", "Y", "U", "V"]\nstep_mm = [0.001, 0.001, 0.001, 0.001]\n\n[compensation]\nd_mm = [0.0, 0.2]\n' \
  >"$work/xyuv.toml"
job() {
  local name="$1"; shift
  "$bin" run "$@" --set gap.kind='"none"' --set output.kind='"file"' \
    --set output.path="\"$work/$name.pulses.csv\"" >/dev/null 2>&1 || echo "$name: exit $?" >>"$work/exits.txt"
}
job die-whole "$work/die.ngc" --config "$work/table.toml"
job die-passes "$work/die.ngc" --config "$work/table.toml" --passes 3
job punch-tab "$work/punch.ngc" --config "$work/tab.toml" --passes 3
job die-tab "$work/die.ngc" --config "$work/tab.toml" --passes 2
job from-line-path tests/data/die-from-line.ngc --set 'compensation.d_mm=[0.0,0.2]' --from-line 13
job from-line-direct tests/data/sink-from-line.ngc --config tests/data/xyz.toml \
  --set machine.safe_z_mm=10 --from-line 5
job orbit tests/data/sink-from-line.ngc --config tests/data/xyz.toml \
  --set 'sinker.orbit.shape="square"' --set sinker.orbit.radius_mm=0.3
job taper "$work/taper.ngc" --config "$work/xyuv.toml"
(cd "$work" && "$bin" check punch.ngc --config table.toml >check-punch.txt 2>&1) || true
(cd "$work" && "$bin" check taper.ngc --config xyuv.toml >check-taper.txt 2>&1) || true
touch "$work/exits.txt"
(cd "$work" && sha256sum ./*.pulses.csv plan-*/* check-*.txt exits.txt | sort -k2)
