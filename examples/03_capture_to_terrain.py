"""A depth capture as terrain

Mesh a depth image (the library's synthetic Kinect v2 view of a plywood bridge, with its
intrinsics beside it), print what perception found (the camera's height and tilt, the
ground's support), then use the capture file directly as a scene: start and goal are picked
where the robot can stand, and a trial runs on it.
"""

import roachplan
from roachplan.scenes import LIBRARY


def main() -> None:
    capture = LIBRARY / "kinect_bridge_depth.png"  # its intrinsics: kinect_bridge_depth.json
    rec = roachplan.mesh(capture, voxel=0.02)
    found = rec.report()
    print(
        f"camera {found['camera_height_m']:.2f} m above the ground, pitched "
        f"{found['pitch_down_deg']:.1f} deg down; ground: {found['ground']['support_points']} "
        f"points; {found['triangles']} triangles"
    )
    for warning in found["warnings"]:
        print("warning:", warning)

    world = roachplan.load(capture)
    for note in world.notes:
        print("note:", note)
    trial = roachplan.trial(world, seed=0)
    print(f"trial on the capture: {trial.outcome}, {trial.drive_time:.1f} s")


if __name__ == "__main__":
    main()
