// The voxelization experiment of Tong 2018, section 3.1 (figure 3.2): a flat wall 6 m in front
// of the camera. Units: metres; the floor's top is z = 0, the wall's face is y = wall_distance.
wall_distance = 6.0;
wall_size = [4.0, 3.0];    // width (x) and height (z) [m]
floor_size = [4.0, 7.0];

translate([-floor_size[0] / 2, -1.0, -0.02]) cube([floor_size[0], floor_size[1], 0.02]);
translate([-wall_size[0] / 2, wall_distance, 0]) cube([wall_size[0], 0.1, wall_size[1]]);
