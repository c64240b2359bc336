(edmd runtime tests: lines, an arc and a NURBS curve joined at corners, about 14 mm,)
(with no fold-backs, so a replayed pulse log tells turn-back moves from forward ones.)
G21 G90 G17
G1 X2 Y0 F600
G1 X4 Y1
G3 X6 Y3 I0 J2
G5.2 X7 Y5 P1 L4
     X8 Y4 P1
     X9 Y6 P2
     X10 Y6 P1
G5.3
G1 X10 Y8
G1 X7.5 Y8.25
M2
