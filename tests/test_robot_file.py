"""Robot files (scenes/_robot_file.py): each value checked by its setting's validator, in a file
and however a RobotFile is made; a scene that names one takes its friction and motors."""

from __future__ import annotations

import pytest

from roachplan import SettingError
from roachplan.scenes import RobotFile, SceneError, load_robot_file, write_robot_file


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("friction: -1\n", "friction: expected a number from 0.05 to 5 [-], got -1"),
        ("friction: 0.7\nmotor_gain: x\n", "motor_gain: expected a finite number [-], got 'x'"),
        ("motor_gain: 1\n", "friction: missing (required)"),
        ("friction: 1\nfoo: 2\n", "foo: unknown key; accepted keys: friction, motor_gain"),
        ("[1]\n", "expected a robot file: a mapping with keys friction"),
        (
            "friction: 1\nmotor_mismatch: 0.7\n",
            "motor_mismatch: expected a number from -0.5 to 0.5",
        ),
    ],
)
def test_a_bad_robot_file_is_refused_naming_the_file_and_key(tmp_path, text, message):
    path = tmp_path / "roach.yaml"
    path.write_text(text)
    with pytest.raises(SceneError) as err:
        load_robot_file(path)
    assert str(err.value).startswith(f"{path}: ")
    assert message in str(err.value)


def test_a_robot_file_is_checked_however_made_and_reads_back(tmp_path):
    with pytest.raises(SettingError, match="mass_scale: expected a number from 0.2 to 5"):
        RobotFile(friction=0.8, mass_scale=0.0)
    robot = RobotFile(friction=0.8, motor_gain=0.95, motor_mismatch=0.03, fitted={"logs": ["a"]})
    write_robot_file(tmp_path / "r.yaml", robot)
    text = (tmp_path / "r.yaml").read_text()
    assert text.startswith("# written by roachplan (robot fit)\n")
    back = load_robot_file(tmp_path / "r.yaml")
    assert (back.friction, back.motor_gain, back.motor_mismatch) == (0.8, 0.95, 0.03)
    left, right = back.robot().motor_gain
    assert left == pytest.approx(0.95 * 1.03) and right == pytest.approx(0.95 * 0.97)
