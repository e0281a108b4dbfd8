// Double bridge of Tong 2018, appendix C.1 (table C.1), with the optional random bumps of
// appendix C.2. Units: metres. Frame: x across the bridges, y along the direction of travel,
// z up; the ground is z = 0 and the structure is centred on the origin.
//
//   a ramp (y in [-1.5, -0.5]) rises from 0 to ramp_height,
//   two bridges (y in [-0.5, 0.5]) of width bridge_width sit at the outer edges
//   with a gap of `separation` between them, and a mirrored ramp comes down.
//
// Bumps (appendix C.2): each bridge top is a bump_columns x bump_rows grid of square pyramids
// (2.5 cm bases for 20 x 40 on a 0.5 x 1.0 m bridge), each peak at a height drawn uniformly
// from [0, max height) by OpenSCAD's seeded rands(). A height of 0 leaves a bridge smooth.

ramp_length = 1.0;
ramp_width = 2.0;
ramp_height = 0.2;
bridge_length = 1.0;
bridge_width = 0.5;
separation = 1.0;

bump_columns = 20;        // pyramids across a bridge (x)
bump_rows = 40;           // pyramids along a bridge (y)
left_bump_height = 0;     // max peak height on the bridge at x < 0 [m]
right_bump_height = 0;    // max peak height on the bridge at x > 0 [m]
bump_seed = 0;            // the left bridge draws with bump_seed, the right with bump_seed + 1

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

// One bridge with its bumps as a single closed polyhedron, corner at the origin. Writing the
// 800 pyramids as one polyhedron (not 800 unioned objects) keeps OpenSCAD's CGAL render of
// the whole scene to about 2 s instead of about 30 s.
module bumpy_bridge(max_height, seed) {
    nx = bump_columns;
    ny = bump_rows;
    sx = bridge_width / nx;
    sy = bridge_length / ny;
    h = rands(0, max_height, nx * ny, seed);
    function corner(i, j) = i * (ny + 1) + j;           // base corners, (nx+1) x (ny+1)
    function peak(i, j) = (nx + 1) * (ny + 1) + i * ny + j;
    b = (nx + 1) * (ny + 1) + nx * ny;                  // the 4 bottom corners follow
    corners = [for (i = [0:nx]) for (j = [0:ny]) [i * sx, j * sy, ramp_height]];
    peaks = [for (i = [0:nx - 1]) for (j = [0:ny - 1])
        [(i + 0.5) * sx, (j + 0.5) * sy, ramp_height + h[i * ny + j]]];
    bottom = [[0, 0, 0], [bridge_width, 0, 0], [bridge_width, bridge_length, 0], [0, bridge_length, 0]];
    // Faces clockwise seen from outside, as polyhedron() wants.
    pyramids = [for (i = [0:nx - 1]) for (j = [0:ny - 1]) each [
        [corner(i, j), corner(i, j + 1), peak(i, j)],
        [corner(i, j + 1), corner(i + 1, j + 1), peak(i, j)],
        [corner(i + 1, j + 1), corner(i + 1, j), peak(i, j)],
        [corner(i + 1, j), corner(i, j), peak(i, j)]]];
    sides = [
        [b, b + 1, b + 2, b + 3],
        concat([b], [for (i = [0:nx]) corner(i, 0)], [b + 1]),
        concat([b + 1], [for (j = [0:ny]) corner(nx, j)], [b + 2]),
        concat([b + 2], [for (i = [nx:-1:0]) corner(i, ny)], [b + 3]),
        concat([b + 3], [for (j = [ny:-1:0]) corner(0, j)], [b])];
    polyhedron(points = concat(corners, peaks, bottom), faces = concat(pyramids, sides));
}

module bridge(max_height, seed) {
    if (max_height > 0) bumpy_bridge(max_height, seed);
    else cube([bridge_width, bridge_length, ramp_height]);
}

union() {
    translate([0, -bridge_length / 2 - ramp_length, 0]) ramp();
    mirror([0, 1, 0]) translate([0, -bridge_length / 2 - ramp_length, 0]) ramp();
    // The bridges sit flush with the ramps' outer edges, `separation` apart.
    translate([-separation / 2 - bridge_width, -bridge_length / 2, 0])
        bridge(left_bump_height, bump_seed);
    translate([separation / 2, -bridge_length / 2, 0])
        bridge(right_bump_height, bump_seed + 1);
}
