#!/usr/bin/env bash
# What a helix costs `edmd check` against LinuxCNC's `rs274 -g`, in instructions (callgrind,
# repeatable on a busy machine): a program of 1,000 helices of radius 10 mm (whole turns
# counter-clockwise and half turns clockwise, each falling 0.1 mm in Z), less the same
# program without them. Needs valgrind and rs274 (Debian's linuxcnc-uspace); prints the
# instructions per helix and the ratio (BENCHMARKS.md, "Helices in check against rs274").
#
#   scripts/helix-cost.sh [EDMD_BINARY]
set -euo pipefail
edmd=$(realpath "${1:-target/release/edmd}")
config=$(realpath "$(dirname "$0")/../tests/data/xyz.toml")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
python3 - "$dir" <<'PY'
import sys
for helices, name in ((True, "helix"), (False, "none")):
    lines = ["G21 G17 G90 F100", "G0 X10 Y0 Z0"]
    for i in range(1000):
        z = -0.1 * (i + 1)
        if helices:
            lines.append(f"G3 X10 Y0 I-10 J0 Z{z:.3f}" if i % 2 == 0 else f"G2 X-10 Y0 I-10 J0 Z{z:.3f}")
        lines.append("G0 X10 Y0")
    lines.append("M2")
    open(f"{sys.argv[1]}/{name}.ngc", "w").write("\n".join(lines) + "\n")
PY
instructions() { valgrind --tool=callgrind --callgrind-out-file=/dev/null "$@" 2>&1 >/dev/null | awk '/Collected/ {gsub(",", "", $4); print $4}'; }
mkdir -p "$dir/home"
e1=$(instructions "$edmd" check "$dir/helix.ngc" -q --config "$config")
e0=$(instructions "$edmd" check "$dir/none.ngc" -q --config "$config")
r1=$(HOME="$dir/home" instructions rs274 -g "$dir/helix.ngc" /dev/null)
r0=$(HOME="$dir/home" instructions rs274 -g "$dir/none.ngc" /dev/null)
echo "edmd check: $(( (e1 - e0) / 1000 )) instructions a helix"
echo "rs274 -g:   $(( (r1 - r0) / 1000 )) instructions a helix"
echo "ratio:      $(echo "($e1 - $e0) / ($r1 - $r0)" | bc -l | cut -c1-4)"
