(Arcs in the three planes, I J K and R forms, full circles, G90.1 absolute centres.)
(Written for edmd after the RS274/NGC arc rules LinuxCNC documents: G17 uses I J,)
(G18 uses K I, Z then X; G19 uses J K; G2 is clockwise seen from the plane's positive normal.)
(Expected feed length: six half circles and a full circle of radius 5, a quarter of radius 5,)
(and a 10 mm line: 37.5 pi + 10 = 127.8097 mm.)
G21 G90 G94 G17
G0 X0 Y0 Z0
F300
(XY: half circle CW over centre X5, then half circle CCW by R, both radius 5)
G2 X10 Y0 I5 J0
G3 X20 Y0 R5
(XY: a full circle, radius 5, centre X15 Y0)
G2 X20 Y0 I-5
(ZX: half circle from X20 to X30 around X25 Z0)
G18 G3 X30 Z0 I5 K0
(YZ: half circle from Y0 to Y10 around Y5 Z0)
G19 G2 Y10 Z0 J5 K0
(YZ again by R, back to Y0: radius 5)
G3 Y0 Z0 R5
(XY with absolute centres: a quarter circle of radius 5 around X30 Y5)
G17 G90.1 G3 X35 Y5 I30 J5
G91.1
(and a straight line to finish)
G1 X35 Y15
M30
