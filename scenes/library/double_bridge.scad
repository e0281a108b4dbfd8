// Double bridge of Tong 2018, appendix C.1 / table C.1. Units: metres.
// Frame: x across the bridges, y along the direction of travel, z up; the
// ground is z = 0 and the structure is centred on the origin.
//
//   ramp (y in [-1.5, -0.5]) rises from 0 to ramp_height,
//   two bridges (y in [-0.5, 0.5]) of width bridge_width sit at the outer edges
//   with a gap of `separation` between them, and a mirrored ramp comes down.

ramp_length = 1.0;
ramp_width = 2.0;
ramp_height = 0.2;
bridge_length = 1.0;
bridge_width = 0.5;
separation = 1.0;

module ramp() {
    // Right triangular prism: rises along +y from 0 to ramp_height.
    polyhedron(
        points = [
            [-ramp_width / 2, 0, 0], [ramp_width / 2, 0, 0],
            [ramp_width / 2, ramp_length, 0], [-ramp_width / 2, ramp_length, 0],
            [-ramp_width / 2, ramp_length, ramp_height], [ramp_width / 2, ramp_length, ramp_height]
        ],
        faces = [[0, 1, 2, 3], [0, 4, 5, 1], [3, 2, 5, 4], [0, 3, 4], [1, 5, 2]]
    );
}

module bridges() {
    for (side = [-1, 1])
        translate([side * (separation + bridge_width) / 2 - bridge_width / 2, -bridge_length / 2, 0])
            cube([bridge_width, bridge_length, ramp_height]);
}

union() {
    translate([0, -bridge_length / 2 - ramp_length, 0]) ramp();
    mirror([0, 1, 0]) translate([0, -bridge_length / 2 - ramp_length, 0]) ramp();
    bridges();
}
