"""The mocap-to-world transform: measured at the start, it puts the robot at the start."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from roachplan.robot import FrameTransform, measure_transform
from roachplan.robot._transform import quat_multiply, yaw_of, yaw_quat

coord = st.floats(-5, 5)
angle = st.floats(-math.pi, math.pi)


@given(x=coord, y=coord, z=st.floats(0, 1), yaw=angle, sx=coord, sy=coord, syaw=angle)
def test_the_transform_measured_at_the_start_maps_the_robot_onto_the_start(
    *, x, y, z, yaw, sx, sy, syaw
):
    tilt = (0.02, -0.01, 0.0, math.sqrt(1 - 0.02**2 - 0.01**2))  # standing a little tilted
    q_mocap = quat_multiply(yaw_quat(yaw), tilt)
    tf = measure_transform((x, y, z), q_mocap, (sx, sy, syaw), 0.025)
    p, q = tf.apply((x, y, z), q_mocap)
    assert p == pytest.approx((sx, sy, 0.025), abs=1e-9)
    assert math.remainder(yaw_of(q) - syaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-6)
    # and a point 10 cm ahead of the robot in the mocap lands 10 cm ahead of the start (to
    # within what the tilt turns its horizontal heading: 0.1 m x 4e-4 rad)
    ahead = (x + 0.1 * math.cos(yaw), y + 0.1 * math.sin(yaw), z)
    p2, _ = tf.apply(ahead, q_mocap)
    assert p2[0] == pytest.approx(sx + 0.1 * math.cos(syaw), abs=1e-4)
    assert p2[1] == pytest.approx(sy + 0.1 * math.sin(syaw), abs=1e-4)


def test_a_given_transform_turns_and_moves():
    tf = FrameTransform.from_xyz_yaw(1.0, 2.0, 0.0, math.pi / 2)
    p, q = tf.apply((1.0, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0))
    assert p == pytest.approx((1.0, 3.0, 0.5))
    assert yaw_of(q) == pytest.approx(math.pi / 2)
