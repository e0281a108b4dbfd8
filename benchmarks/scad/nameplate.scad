// A desk name plate, Thingiverse style: a plate with rounded edges and countersunk holes,
// engraved subtitle, raised label with softened (minkowski) edges, and an `include` of shared
// helpers. Millimetres.
include <parts.scad>

label = "ROACHPLAN";
subtitle = "hexapod terrain lab";
width = 140;
depth = 45;
thickness = 4;
edge = 1.2;        // rounding of the plate's edges
font = "DejaVu Sans:style=Bold";

difference() {
    minkowski() {
        translate([edge, edge, edge]) rounded_box([width - 2 * edge, depth - 2 * edge, thickness - 2 * edge], r = 4);
        sphere(r = edge, $fn = 16);
    }
    for (x = [8, width - 8]) translate([x, depth / 2, 0]) screw_hole(depth = thickness);
    translate([width / 2, 8, thickness - 1])
        linear_extrude(2) text(subtitle, size = 6, font = "DejaVu Sans", halign = "center");
}
translate([width / 2, 18, thickness - 0.5])
    minkowski() {
        linear_extrude(2) text(label, size = 14, font = font, halign = "center");
        sphere(r = 0.5, $fn = 8);
    }
