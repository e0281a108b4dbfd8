// A vented electronics box, Thingiverse style: rounded walls, a honeycomb floor vent, screw posts
// and an embossed label, with the helpers `use`d from a shared file. Millimetres.
use <parts.scad>

inner = [80, 60, 30];
wall = 2;
label = "ROACH-01";
$fn = 40;

outer = inner + [2 * wall, 2 * wall, wall];
difference() {
    rounded_box(outer, r = 4);
    translate([wall, wall, wall]) rounded_box([inner[0], inner[1], inner[2] + 1], r = 2);
    translate([10, 10, -1]) honeycomb([outer[0] - 20, outer[1] - 20, wall + 2], cell = 5, wall = 1.2);
    translate([outer[0] / 2, -0.01, outer[2] / 2]) rotate([90, 0, 0]) mirror([0, 1, 0])
        translate([0, 0, -0.8]) linear_extrude(1)
            text(label, size = 8, font = "DejaVu Sans", halign = "center", valign = "center");
}
for (x = [wall + 4, outer[0] - wall - 4], y = [wall + 4, outer[1] - wall - 4])
    translate([x, y, wall]) difference() {
        cylinder(d = 7, h = inner[2] - 2);
        cylinder(d = 2.8, h = inner[2]);
    }
