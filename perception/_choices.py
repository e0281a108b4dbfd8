"""The pipeline's named choices, importable without trimesh or Open3D (the command line builds
its --method and --frame choices from them and must answer at once)."""

from __future__ import annotations

from typing import Literal

Method = Literal["sensor", "grid", "poisson", "ball-pivot"]
METHODS: tuple[str, ...] = ("sensor", "grid", "poisson", "ball-pivot")
Frame = Literal["auto", "camera", "world"]
FRAMES: tuple[str, ...] = ("auto", "camera", "world")
