// Helpers of the kind Thingiverse models share through `include`: rounded boxes, countersunk
// screw holes, a honeycomb vent. Units are millimetres, as in nearly every public model.

module rounded_box(size, r = 3, $fn = 48) {
    hull()
        for (x = [r, size[0] - r], y = [r, size[1] - r])
            translate([x, y, 0]) cylinder(r = r, h = size[2]);
}

module screw_hole(d = 3.4, head = 6.5, depth = 10, $fn = 40) {
    translate([0, 0, -0.01]) cylinder(d = d, h = depth + 0.02);
    translate([0, 0, depth - (head - d) / 2]) cylinder(d1 = d, d2 = head, h = (head - d) / 2 + 0.01);
}

module honeycomb(size, cell = 6, wall = 1.2) {
    dx = cell + wall;
    dy = dx * sqrt(3) / 2;
    intersection() {
        cube(size);
        for (j = [0 : size[1] / dy], i = [0 : size[0] / dx])
            translate([i * dx + (j % 2) * dx / 2, j * dy, -0.01])
                rotate([0, 0, 30]) cylinder(d = cell / cos(30), h = size[2] + 0.02, $fn = 6);
    }
}
