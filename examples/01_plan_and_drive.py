"""Plan and drive

Load a library scene, plan one path with OMPL and drive the roach along it in PyBullet: the
same trial as `roachplan trial --scene double_bridge --seed 3`.
"""

import roachplan


def main() -> None:
    world = roachplan.load("double_bridge")  # a name, a scene .yaml, or any terrain file
    print(f"start {world.scene.start}, goal {world.scene.goal} (x [m], y [m], yaw [rad])")

    path = roachplan.plan(world, seed=3)
    print(f"planned {len(path.path_xyz)} waypoints in {path.plan_time:.2f} s ({path.planner})")

    trial = roachplan.drive(world, path)
    print(
        f"{trial.outcome}: {trial.drive_time:.1f} s, {trial.energy:.2f} J, "
        f"relative energy {trial.relative_energy:.2f}, route {trial.route or '-'}"
    )

    again = roachplan.trial(world, seed=3)  # plan + drive: the same seed, the same trial
    assert (again.outcome, again.energy) == (trial.outcome, trial.energy)


if __name__ == "__main__":
    main()
