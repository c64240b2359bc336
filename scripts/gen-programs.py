#!/usr/bin/env python3
"""Generates the four programs edmd is measured on against LinuxCNC's interpreter
(BENCHMARKS.md, "edmd against LinuxCNC's interpreter"), into DIR:

  lines.ngc   200,000 `G1 X Y Z` lines, 4 decimals
  arcs.ngc    20,000 `G2`/`G3` arcs (centre format)
  nurbs.ngc   5,000 cubic `G5.2` curves of 4 control points
  loop.ngc    a 100,000-iteration `while` loop with SIN/COS and parameters

and, named on the command line (not made otherwise), the two `edmd plan` is measured on for
its memory (BENCHMARKS.md, "plan in flat memory"):

  moves.ngc   9,000 `G1` moves of 10 mm
  million.ngc 1,000,000 `G1` moves of 20 to 60 µm

Every program runs on a three-axis (X, Y, Z) mm machine, is accepted by both and ends where
both say it ends. Seeded: the same files every time.

Usage: scripts/gen-programs.py DIR [NAME...]   (NAME: lines arcs nurbs loop moves million)
"""

import math
import random
import sys
from pathlib import Path

HEADER = "G21 G90 G17 G40 G49 G54 G94\nG0 X0 Y0 Z0\nF600\n"


def lines(rng):
    out = [HEADER]
    for i in range(200_000):
        x = 50 * math.sin(i * 0.001) + rng.uniform(-0.5, 0.5)
        y = 50 * math.cos(i * 0.0013) + rng.uniform(-0.5, 0.5)
        z = rng.uniform(-1, 0)
        out.append(f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f}\n")
    out.append("M2\n")
    return "".join(out)


def arcs(rng):
    # Half circles alternating in direction, walking along X: each ends exactly where the
    # centre format says (I is half the chord), so both interpreters agree on every end.
    out = [HEADER, "G1 X0 Y0 Z0\n"]
    x = 0.0
    for i in range(20_000):
        r = rng.choice([0.5, 1.0, 1.5, 2.0])
        word = "G2" if i % 2 == 0 else "G3"
        x += 2 * r
        out.append(f"{word} X{x:.4f} Y0 I{r:.4f} J0\n")
        if x > 400:
            out.append("G0 X0 Y0\n")
            x = 0.0
    out.append("M2\n")
    return "".join(out)


def nurbs(rng):
    # Cubic curves (L4) of four control points from the current point, weights 1.
    out = [HEADER, "G1 X0 Y0\n"]
    x, y = 0.0, 0.0
    for i in range(5_000):
        pts = []
        for _ in range(3):
            x += rng.uniform(0.2, 1.0)
            y = rng.uniform(-2, 2)
            pts.append((x, y))
        out.append(f"G5.2 X{pts[0][0]:.4f} Y{pts[0][1]:.4f} P1 L4\n")
        for px, py in pts[1:]:
            out.append(f"X{px:.4f} Y{py:.4f} P1\n")
        out.append("G5.3\n")
        if x > 400:
            out.append("G0 X0 Y0\n")
            x, y = 0.0, 0.0
            out.append("G1 X0 Y0\n")
    out.append("M2\n")
    return "".join(out)


def loop(_rng):
    return HEADER + """#1 = 0
#2 = 0.05
o100 while [#1 LT 100000]
  #3 = [10 * SIN[#1 * #2]]
  #4 = [10 * COS[#1 * #2]]
  G1 X#3 Y#4 Z[#1 MOD 7 / 10]
  #1 = [#1 + 1]
o100 endwhile
M2
"""


def moves(rng):
    # A zig-zag of 10 mm moves at varying angles, inside a 100 mm square.
    out = [HEADER, "G1 X0 Y0\n"]
    x, y = 0.0, 0.0
    for _ in range(9_000):
        a = rng.uniform(0, 2 * math.pi)
        nx, ny = x + 10 * math.cos(a), y + 10 * math.sin(a)
        if abs(nx) > 50 or abs(ny) > 50:
            nx, ny = x - 10 * math.cos(a), y - 10 * math.sin(a)
        x, y = nx, ny
        out.append(f"G1 X{x:.4f} Y{y:.4f}\n")
    out.append("M2\n")
    return "".join(out)


def million(rng):
    # A million short moves, 20 to 60 µm each, wandering round the origin.
    out = [HEADER, "G1 X0 Y0\n"]
    x, y = 0.0, 0.0
    for i in range(1_000_000):
        a = i * 0.001 + rng.uniform(-0.5, 0.5)
        d = rng.uniform(0.02, 0.06)
        x, y = x + d * math.cos(a), y + d * math.sin(a)
        out.append(f"G1 X{x:.4f} Y{y:.4f}\n")
    out.append("M2\n")
    return "".join(out)


PROGRAMS = {"lines": lines, "arcs": arcs, "nurbs": nurbs, "loop": loop, "moves": moves, "million": million}


def main():
    if len(sys.argv) < 2 or any(n not in PROGRAMS for n in sys.argv[2:]):
        sys.exit(__doc__)
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    for name in sys.argv[2:] or ["lines", "arcs", "nurbs", "loop"]:
        (out / f"{name}.ngc").write_text(PROGRAMS[name](random.Random(39)))
        print(out / f"{name}.ngc")


if __name__ == "__main__":
    main()
