"""The double bridge as rendered by the real OpenSCAD binary matches table C.1, and the
planner's height field and validity conditions see it right."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from roachplan.planning import (
    COLLISION,
    FOOT,
    OFF_MAP,
    VALID,
    HeightField,
    ValidityConfig,
    check_states,
    describe_state,
)
from roachplan.scenes import load_scene, render_scad


def test_rendered_double_bridge_matches_table_c1(world):
    m = world.mesh
    np.testing.assert_allclose(m.bounds, [[-1.0, -1.5, 0.0], [1.0, 1.5, 0.2]], atol=1e-6)
    assert m.is_watertight
    # Two ramps of 1.0 x 2.0 x 0.2 / 2 and two bridges of 1.0 x 0.5 x 0.2.
    assert m.volume == pytest.approx(2 * 0.2 + 2 * 0.1, rel=1e-5)
    nz = m.face_normals[:, 2]
    z = m.triangles_center[:, 2]
    # Bridge tops: two 1.0 x 0.5 m rectangles at 0.2 m, at |x| in [0.5, 1.0] (1.0 m apart).
    top = (nz > 0.999) & (np.abs(z - 0.2) < 1e-5)
    assert m.area_faces[top].sum() == pytest.approx(2 * 1.0 * 0.5, rel=1e-5)
    assert np.all(np.abs(m.triangles_center[top, 0]) >= 0.5 - 1e-6)
    # Ramp faces: 2.0 m wide, rising 0.2 m over 1.0 m.
    ramp = (nz > 0.9) & (nz < 0.999)
    assert m.area_faces[ramp].sum() == pytest.approx(2 * 2.0 * np.hypot(1.0, 0.2), rel=1e-5)
    assert np.allclose(nz[ramp], 1 / np.hypot(1.0, 0.2), atol=1e-5)


def test_openscad_render_is_cached_and_parameters_render_anew():
    scad = load_scene("double_bridge").terrain[0].source
    first = render_scad(scad)
    mtime = first.stat().st_mtime_ns
    assert render_scad(scad) == first and first.stat().st_mtime_ns == mtime
    wider = render_scad(scad, {"separation": 0.8, "ramp_width": 1.8})
    assert wider != first
    assert trimesh.load(wider).extents[0] == pytest.approx(1.8, abs=1e-6)


@pytest.mark.parametrize(
    ("xy", "z"),
    [
        ((0.0, -1.6), 0.0),
        ((0.0, -1.0), 0.1),
        ((0.75, 0.0), 0.2),
        ((0.0, 0.0), 0.0),
        ((0.3, 1.25), 0.05),
    ],
)
def test_heightfield_follows_the_surface(world, xy, z):
    assert world.heightfield.sample(np.array(xy)) == pytest.approx(z, abs=2e-3)


def test_validity_conditions_on_the_double_bridge(world):
    hf, fp, cfg = world.heightfield, world.footprint, ValidityConfig()
    up = np.pi / 2
    states = np.array(
        [
            [0.0, -1.6, up],  # start, on the floor
            [0.75, 0.0, up],  # middle of a bridge
            [0.52, 0.0, up],  # left feet over the gap
            [0.0, -0.5, up],  # front legs past the ramp top edge, over the gap
            [0.75, 0.0, 0.0],  # across a bridge: fits (0.5 m wide), valid
            [5.0, 5.0, 0.0],  # off the map
        ]
    )
    codes = check_states(hf, fp, cfg, states).code
    assert codes[0] == VALID and codes[1] == VALID and codes[4] == VALID
    assert codes[2] in (FOOT, COLLISION)
    assert codes[3] in (FOOT, COLLISION)
    assert codes[5] == OFF_MAP
    # Facing +x at the bridge's inner edge, the rear legs hang over the gap.
    assert describe_state(hf, fp, cfg, np.array([0.53, 0.0, 0.0])).endswith("(leg L3)")
    assert describe_state(hf, fp, cfg, np.array([0.0, -0.5, up])).startswith("a foot has no ground")


def test_many_states_are_checked_in_chunks_as_at_once(world, monkeypatch):
    """A batch larger than a chunk (a standable map's 300,000 states) gives what one call on
    all of them gives, state for state; height and noise sampled together are what they are
    sampled alone."""
    import roachplan.planning._validity as validity

    hf, fp, cfg = world.heightfield, world.footprint, ValidityConfig()
    rng = np.random.default_rng(0)
    n = 3 * validity.CHUNK + 17
    states = np.column_stack(
        [rng.uniform(-1.2, 1.2, n), rng.uniform(-2.0, 2.0, n), rng.uniform(-np.pi, np.pi, n)]
    )
    chunked = check_states(hf, fp, cfg, states)
    monkeypatch.setattr(validity, "CHUNK", n)
    whole = check_states(hf, fp, cfg, states)
    assert whole.valid.any() and not whole.valid.all()
    for field in ("code", "worst_foot", "z_surface"):
        assert np.array_equal(getattr(chunked, field), getattr(whole, field))
    heights = rng.normal(0.0, 0.01, (40, 60))
    heights[10:14, 20:30] = np.nan
    noisy = HeightField(x0=-0.3, y0=-0.2, resolution=0.01, heights=heights,
                        noise=rng.uniform(0.0, 0.002, (40, 60)))  # fmt: skip
    xy = rng.uniform(-0.35, 0.35, (5000, 2))
    h, noise = noisy.sample_with_noise(xy)
    assert np.isnan(h).any() and np.isfinite(h).any()
    assert np.array_equal(h, noisy.sample(xy), equal_nan=True)
    assert np.array_equal(noise, noisy.sample_noise(xy))
