// Settings of the terrain tile, in millimetres (tile.scad includes this file).
tile_size = [80, 60];      // footprint [mm]
base_height = 3;           // the slab under the terrain [mm]
corner_radius = 4;         // rounded corners of the slab [mm]
hill_height = 6;           // highest point of the terrain above the slab [mm]
cells = [16, 12];          // height-field cells of the terrain
label = "ROACH 7";         // embossed on the flat strip at the front
label_size = 6;            // [mm]
emboss = 0.6;              // how far the label stands out [mm]
$fn = 32;
