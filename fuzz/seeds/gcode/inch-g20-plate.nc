%
O0002 (A 2 x 1 inch plate with 0.25 inch corner radii, inch units and incremental moves.)
(Posted the way Fanuc-style inch programs are: G20, trailing decimal points, N words.)
(Expected: feed length 4 in straight + 4 quarter arcs of radius 0.25 in = 5.5708 in = 141.498 mm.)
N1 G20 G17 G40 G49 G80 G90 G94
N2 G0 X.25 Y0.
N3 G1 X1.75 F20.
N4 G3 X2. Y.25 I0. J.25
N5 G91 G1 Y.5
N6 G3 X-.25 Y.25 R.25
N7 G1 X-1.5
N8 G3 X-.25 Y-.25 I0. J-.25
N9 G1 Y-.5
N10 G3 X.25 Y-.25 I.25 J0.
N11 G90 G0 X0. Y0.
N12 M30
%
