// A fan shroud with a honeycomb grille, screw posts and softened (minkowski) mounting tabs,
// helpers `use`d from a shared file: a CSG-heavy public-style model without text(). Millimetres.
use <parts.scad>

size = [92, 92, 12];
wall = 2;
$fn = 48;

difference() {
    rounded_box(size, r = 6);
    translate([wall, wall, wall]) rounded_box([size[0] - 2 * wall, size[1] - 2 * wall, size[2]], r = 4);
    translate([8, 8, -1]) honeycomb([size[0] - 16, size[1] - 16, wall + 2], cell = 6, wall = 1.2);
    for (x = [4.5, size[0] - 4.5], y = [4.5, size[1] - 4.5])
        translate([x, y, 0]) screw_hole(depth = wall + 0.5);
}
for (x = [-12, size[0] + 2])
    translate([x, size[1] / 2 - 10, 0]) minkowski() {
        cube([10, 20, 2]);
        cylinder(r = 1.5, h = 0.5, $fn = 16);
    }
