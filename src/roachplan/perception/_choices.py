"""The pipeline's named choices, importable without trimesh or Open3D (the command line builds
its --method and --frame choices from them and must answer at once)."""

from __future__ import annotations

from typing import Literal

Method = Literal["sensor", "grid", "poisson", "ball-pivot"]
METHODS: tuple[str, ...] = ("sensor", "grid", "poisson", "ball-pivot")
Frame = Literal["auto", "camera", "world"]
FRAMES: tuple[str, ...] = ("auto", "camera", "world")
DepthUnits = Literal["kinect-disparity"]
DEPTH_UNITS: tuple[str, ...] = ("kinect-disparity",)
"""What a depth image's samples may be besides depth in units of its depth scale (the default,
which needs no name): "kinect-disparity", a Kinect v1's raw 11-bit disparity (2047 = no
reading), as NYU Depth v2's raw dumps hold it."""
