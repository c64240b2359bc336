#!/usr/bin/env bash
# How many of LinuxCNC's own sample programs `edmd check` accepts on an X/Y/Z machine, and why
# it refuses the rest. The programs are not part of this repository: pass a LinuxCNC checkout.
#
#   scripts/linuxcnc-acceptance.sh PATH/TO/linuxcnc [EDMD]
#
# Each program is checked from its own directory. "motion" programs produce moves; "definitions
# only" files hold subroutines that nothing in them calls (LinuxCNC runs them as no-ops too).
set -euo pipefail
root=${1:?usage: $0 LINUXCNC_CHECKOUT [EDMD_BINARY]}
edmd=$(realpath "${2:-target/release/edmd}")
sets=(--set 'machine.axes=["X","Y","Z"]' --set 'machine.step_mm=[0.001,0.001,0.001]')
total=0 motion=0 defs=0
reasons=$(mktemp)
while IFS= read -r -d '' f; do
  total=$((total + 1))
  if out=$(cd "$(dirname "$f")" && timeout 20 "$edmd" check "$f" "${sets[@]}" 2>&1); then
    if grep -q '^blocks: 0 ' <<<"$out"; then defs=$((defs + 1)); else motion=$((motion + 1)); fi
  else
    grep -m1 'error:' <<<"$out" | sed -E 's/^edmd: error: [^:]*:[0-9]+:[0-9]+: //; s/[0-9]+(\.[0-9]+)?/N/g' >>"$reasons" || echo "(no message)" >>"$reasons"
  fi
done < <(find "$root/nc_files" -name '*.ngc' -print0 | sort -z)
echo "checked $total programs: $((motion + defs)) accepted ($motion with motion, $defs definitions only), $((total - motion - defs)) refused"
sort "$reasons" | uniq -c | sort -rn
rm -f "$reasons"
