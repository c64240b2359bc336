%
O1000 (Fanuc G06.2 NURBS: the ten-point cubic of the Fanuc/LinuxCNC NURBS examples)
(Control points and knots as published with the check value at u = 3.5: X37.943895833 Y55.599625;)
(weights 1, so R is left out. One control point and one knot per block, then four)
(knot-only blocks, one per order P4, close the curve.)
N10 G21 G90 G17 G40 G49 G80 G94
N20 G00 X0 Y100
N30 G06.2 P4 K0 X0 Y100 F600
N40 K0 X10 Y100
N50 K0 X10 Y70.665
N60 K0 X27.928 Y59.258
N70 K1 X34.093 Y56.935
N80 K2 X41.136 Y54.281
N90 K3 X63.112 Y51.556
N100 K4 X79.999 Y60
N110 K5 X99.998 Y40.002
N120 K6 X100 Y0.012
N130 K7
N140 K7
N150 K7
N160 K7
N170 G01 X100 Y-10
N180 M30
%
