// Modules of the terrain tile (tile.scad uses this file), in the manner of public tile models.

// A slab with rounded corners: the hull of four cylinders.
module rounded_slab(size, height, r) {
    hull() for (x = [r, size[0] - r], y = [r, size[1] - r])
        translate([x, y, 0]) cylinder(r = r, h = height);
}

// Height of the terrain at (x, y) [mm]: two smooth hills, no randomness.
function hill(x, y, size, height) =
    height * (0.55 + 0.25 * sin(360 * x / size[0]) * cos(180 * y / size[1])
              + 0.2 * cos(540 * x / size[0] + 90 * y / size[1])) / 1.0;

// The terrain as one polyhedron: a height field over `cells` from z = 0 up. Its faces are
// listed counter-clockwise seen from outside, the other way from what OpenSCAD asks (as
// many generated public models do): OpenSCAD's CGAL still makes a solid of it.
module height_field(size, cells, height) {
    nx = cells[0] + 1;
    ny = cells[1] + 1;
    top = [for (j = [0:ny - 1]) for (i = [0:nx - 1])
           [size[0] * i / cells[0], size[1] * j / cells[1],
            hill(size[0] * i / cells[0], size[1] * j / cells[1], size, height)]];
    bottom = [for (j = [0:ny - 1]) for (i = [0:nx - 1])
              [size[0] * i / cells[0], size[1] * j / cells[1], 0]];
    n = nx * ny;
    faces = concat(
        // top, counter-clockwise seen from above (outside)
        [for (j = [0:ny - 2]) for (i = [0:nx - 2])
            [j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i]],
        // bottom, counter-clockwise seen from below
        [for (j = [0:ny - 2]) for (i = [0:nx - 2])
            [n + j * nx + i, n + (j + 1) * nx + i, n + (j + 1) * nx + i + 1, n + j * nx + i + 1]],
        // sides y = 0 and y = max, x = 0 and x = max
        [for (i = [0:nx - 2]) [i, n + i, n + i + 1, i + 1]],
        [for (i = [0:nx - 2]) [(ny - 1) * nx + i + 1, n + (ny - 1) * nx + i + 1,
                                n + (ny - 1) * nx + i, (ny - 1) * nx + i]],
        [for (j = [0:ny - 2]) [(j + 1) * nx, n + (j + 1) * nx, n + j * nx, j * nx]],
        [for (j = [0:ny - 2]) [j * nx + nx - 1, n + j * nx + nx - 1,
                                n + (j + 1) * nx + nx - 1, (j + 1) * nx + nx - 1]]
    );
    polyhedron(concat(top, bottom), faces, convexity = 6);
}

// Text standing `height` up from z = 0, centred on the origin.
module label_text(text, size, height, font = "") {
    linear_extrude(height)
        text(text, size = size, font = font, halign = "center", valign = "center");
}
