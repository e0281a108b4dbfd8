// The plywood bridge of Tong 2018, section 6.3 (figures 6.4-6.6): a plywood plank on cinder
// blocks, with plywood ramps (paper smoothing the joints) up from the floor at both ends, and
// the floor it stands on. Units: metres. Frame: x along the bridge, z up, floor top at z = 0.
// The report gives no dimensions; these are a plausible build: half-height blocks (10 cm),
// 2 cm plywood, a 30 cm wide plank, 40 cm ramps (17 degrees).

plank_length = 0.9;
plank_width = 0.30;
plank_thickness = 0.02;
block_height = 0.10;       // cinder blocks under the plank [m]
block_size = [0.19, 0.39]; // their footprint, x by y [m]
ramp_length = 0.40;
floor_size = [3.4, 2.4];   // the captured floor around it [m]
floor_thickness = 0.02;

top = block_height + plank_thickness;

// The floor: its top at z = 0.
translate([-floor_size[0] / 2, -floor_size[1] / 2, -floor_thickness])
    cube([floor_size[0], floor_size[1], floor_thickness]);

// Cinder blocks at both ends and the middle of the plank.
for (x = [-plank_length / 2 + block_size[0] / 2, 0, plank_length / 2 - block_size[0] / 2])
    translate([x - block_size[0] / 2, -block_size[1] / 2, 0])
        cube([block_size[0], block_size[1], block_height]);

// The plank.
translate([-plank_length / 2, -plank_width / 2, block_height])
    cube([plank_length, plank_width, plank_thickness]);

// Ramps: wedges rising from the floor to the plank's top at each end.
module ramp() {
    polyhedron(
        points = [
            [0, -plank_width / 2, 0], [0, plank_width / 2, 0],
            [ramp_length, -plank_width / 2, 0], [ramp_length, plank_width / 2, 0],
            [ramp_length, -plank_width / 2, top], [ramp_length, plank_width / 2, top],
        ],
        faces = [[0, 2, 3, 1], [2, 4, 5, 3], [0, 1, 5, 4], [0, 4, 2], [1, 3, 5]]
    );
}
translate([-plank_length / 2 - ramp_length, 0, 0]) ramp();
translate([plank_length / 2 + ramp_length, 0, 0]) mirror([1, 0, 0]) ramp();
