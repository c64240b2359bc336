#!/usr/bin/env bash
# edmd against LinuxCNC's interpreter: instructions (callgrind, repeatable on a busy machine)
# and wall time of `edmd check P --quiet` and `rs274 -g P /dev/null` on the four programs of
# scripts/gen-programs.py, and where each ends. Needs valgrind and rs274 (Debian's
# linuxcnc-uspace); prints a Markdown table (BENCHMARKS.md, "edmd against LinuxCNC's
# interpreter").
#
#   scripts/vs-linuxcnc.sh [EDMD_BINARY]
set -euo pipefail
edmd=$(realpath "${1:-target/release/edmd}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
python3 "$(dirname "$0")/gen-programs.py" "$dir" >/dev/null
sets=(--set 'machine.axes=["X","Y","Z"]' --set 'machine.step_mm=[0.001,0.001,0.001]')
instructions() { valgrind --tool=callgrind --callgrind-out-file=/dev/null "$@" 2>&1 >/dev/null | awk '/Collected/ {print $4}'; }
wall() { /usr/bin/time -f %e "$@" 2>&1 >/dev/null | tail -1; }
echo "rs274: $(dpkg-query -W -f '${Package} ${Version}' linuxcnc-uspace 2>/dev/null || echo unknown)"
echo
echo "| program | edmd check (instr) | rs274 (instr) | ratio | edmd wall (s) | rs274 wall (s) | end (edmd) |"
echo "|---|---|---|---|---|---|---|"
for p in lines arcs nurbs loop; do
  f="$dir/$p.ngc"
  a=$(instructions "$edmd" check "$f" --quiet "${sets[@]}")
  b=$(instructions rs274 -g "$f" /dev/null)
  wa=$(wall "$edmd" check "$f" --quiet "${sets[@]}")
  wb=$(wall rs274 -g "$f" /dev/null)
  end=$("$edmd" check "$f" --quiet "${sets[@]}" | sed -n 's/^end position: //p')
  printf '| %s | %s | %s | %.2f | %s | %s | %s |\n' "$p" "$a" "$b" "$(echo "$a / $b" | bc -l)" "$wa" "$wb" "$end"
done
