// A terrain tile in millimetres, in the manner of public tabletop tiles: settings from an
// include, modules from a use, a height-field polyhedron, an embossed label and an engraved
// maker's mark. Load it as terrain with `scale: 0.02` (80 mm -> 1.6 m) on `ground: 0`.
include <tile_settings.scad>
use <tile_parts.scad>

strip = 14;  // the flat strip at the front, for the label [mm]

difference() {
    union() {
        rounded_slab(tile_size, base_height, corner_radius);
        translate([0, strip, base_height - 0.01])
            height_field([tile_size[0], tile_size[1] - strip], cells, hill_height);
        translate([tile_size[0] / 2, strip / 2, base_height - 0.01])
            label_text(label, label_size, emboss + 0.01);
    }
    // The maker's mark, engraved in the slab's front face.
    translate([tile_size[0] - 12, 0.5, base_height / 2]) rotate([90, 0, 0])
        label_text("v2", 2, 1, font = "Liberation Sans:style=Bold");
}
