"""Robot files: the simulation's parameters of one real robot, as roachplan.robot.fit finds
them from its logged runs, for scenes to name (`robot: {file: my_roach.yaml}`).

    # written by roachplan (robot fit)
    friction: 0.71         # Coulomb friction of its feet on this floor [-] (the scene's sim.friction)
    motor_gain: 0.95       # both motors' speed / their command [-]
    motor_mismatch: 0.03   # left x (1 + d), right x (1 - d) [-]
    mass_scale: 1.0        # its body's mass / the model's 24 g [-]
    fitted: {...}          # what it was fitted to and how well (not read back)

Every key but `fitted` is checked by its setting's validator (roachplan/_settings.py) whenever a
RobotFile is made; a file's error names the file, the key and what is accepted.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from roachplan._settings import between, check_settings
from roachplan._settings import setting as s
from roachplan.perception import short_repr
from roachplan.sim import RobotConfig

from ._errors import SceneError

RANGES = {
    "friction": (0.05, 5.0),
    "motor_gain": (0.2, 5.0),
    "motor_mismatch": (-0.5, 0.5),
    "mass_scale": (0.2, 5.0),
}
"""(low, high) of each parameter: outside them a fit went wrong or the file was mistyped."""


@dataclass(frozen=True, kw_only=True)
class RobotFile:
    """One real robot's simulation parameters, each checked by its validator however made."""

    friction: float = s(0.9, between(*RANGES["friction"], "-"))
    """Coulomb friction of its feet on the floor it ran on [-] (the scene's sim.friction)."""
    motor_gain: float = s(1.0, between(*RANGES["motor_gain"], "-"))
    """Both motors' speed / their command [-]."""
    motor_mismatch: float = s(0.0, between(*RANGES["motor_mismatch"], "-"))
    """Left x (1 + d), right x (1 - d) [-]."""
    mass_scale: float = s(1.0, between(*RANGES["mass_scale"], "-"))
    """Its body's mass / the model's [-]."""
    fitted: dict | None = None
    """Provenance: the logs, the errors before and after (written, not read back)."""

    def __post_init__(self) -> None:
        check_settings(self)

    def robot(self, base: RobotConfig | None = None) -> RobotConfig:
        """base (default: the nominal roach) with this robot's motors and body mass."""
        base = base or RobotConfig()
        g, d = self.motor_gain, self.motor_mismatch
        return dataclasses.replace(
            base, body_mass=base.body_mass * self.mass_scale, motor_gain=(g * (1 + d), g * (1 - d))
        )

    def to_yaml(self) -> str:
        data: dict[str, Any] = {
            "friction": round(float(self.friction), 6),
            "motor_gain": round(float(self.motor_gain), 6),
            "motor_mismatch": round(float(self.motor_mismatch), 6),
            "mass_scale": round(float(self.mass_scale), 6),
        }
        if self.fitted is not None:
            data["fitted"] = self.fitted
        return ROBOT_FILE_HEADER + yaml.safe_dump(data, sort_keys=False)


ROBOT_FILE_HEADER = "# written by roachplan (robot fit)\n"
"""The first line of every robot file roachplan writes (`fit -o` replaces such a file)."""


def load_robot_file(path: Path) -> RobotFile:
    """Read and check a robot file (friction required; each value by its setting's validator);
    SceneError naming the file, the key and what is accepted."""
    from ._scene import YamlFields, read_yaml

    ctx = YamlFields(path)
    raw = read_yaml(path, "robot", SceneError)
    if not isinstance(raw, dict):
        raise SceneError(
            f"{path}: expected a robot file: a mapping with keys {', '.join(RANGES)} (friction "
            f"required), got {short_repr(raw)}"
        )
    data = ctx.mapping(raw, "", (*RANGES, "fitted"), required=("friction",))
    if not isinstance(data.get("fitted"), dict | None):
        data = {k: v for k, v in data.items() if k != "fitted"}  # (provenance only)
    return ctx.config(RobotFile, data, "")


def write_robot_file(path: Path, robot: RobotFile) -> None:
    """Write atomically (a temporary file beside it, then renamed)."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(robot.to_yaml())
    tmp.replace(path)
