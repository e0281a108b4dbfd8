// A height-map terrain (Tong 2018, section 5.1: OpenSCAD "can also generate height maps"):
// rolling ground with a ramped plateau, read by surface() from heightmap.dat (heights in cm on
// a 5 cm grid; scripts/make_heightmap.py writes it). Units: metres, z up.

spacing = 0.05;     // grid spacing of heightmap.dat [m]
z_scale = 0.01;     // heightmap.dat is in centimetres

// surface() spans (columns - 1) x (rows - 1) units, centred in x and y with center = true;
// its solid reaches from the surface down to 1 unit below the lowest value.
scale([spacing, spacing, z_scale])
    surface(file = "heightmap.dat", center = true, convexity = 5);
