"""Property-based fuzzing of the scene loader and its YAML reader (issue 15): whatever a scene file
holds, load_scene loads it or raises SceneError, never another exception, and load_yaml reads
any text or raises its error. Brief in `make test` (profile "test"), long in `make fuzz`."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh
import yaml
from hypothesis import given
from hypothesis import strategies as st

from roachplan.perception import MAX_YAML_BYTES, load_yaml, short_repr
from roachplan.scenes import Scene, SceneError, load_scene

SCENE_KEYS = (
    "description",
    "terrain",
    "ground",
    "robot",
    "goal",
    "bounds",
    "routes",
    "planner",
    "sim",
    "driver",
    "seed",
)
OBJECT_KEYS = (
    "scad",
    "mesh",
    "capture",
    "params",
    "timeout",
    "perception",
    "scale",
    "position",
    "orientation",
)
CONFIG_KEYS = (
    "name",
    "time_limit",
    "max_iterations",
    "prm_batch",
    "simplify",
    "validity",
    "timestep",
    "solver_iterations",
    "friction",
    "omega0",
    "gain",
    "r_end",
)
PERCEPTION_KEYS = (
    "voxel",
    "method",
    "intrinsics",
    "depth_scale",
    "units",
    "topic",
    "crop",
    "depth_range",
    "seed",
    "frame",
    "up",
)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A scene folder with a mesh, a .scad model (top-level variables and a module's parameter)
    and a capture file for terrain objects to name."""
    root = tmp_path_factory.mktemp("fuzz")
    trimesh.creation.box((1.0, 1.0, 0.1)).export(root / "block.stl")
    (root / "m.scad").write_text(
        'size = 2;\nunit = size / 2;\nlabel = "x";\nsolid = true;\ndims = [1, 2, 3];\n'
        "module post(width = 1) { cube([width, 1, size]); }\npost();\n"
    )
    (root / "cloud.pcd").write_text("# not read while loading\n")
    return root


scalars = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.integers(min_value=-(10**30), max_value=10**30)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=20)
    | st.sampled_from(
        [
            "1e6",
            "prm",
            "rrtconnect",
            "block.stl",
            "m.scad",
            "cloud.pcd",
            "x\0y",
            "../block.stl",
            "/etc/passwd",
            "m",
            "kinect_v2",
            "a" * 300,
        ]
    )
)
values = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=5)
        | st.dictionaries(st.text(max_size=8) | st.sampled_from(CONFIG_KEYS), inner, max_size=4)
    ),
    max_leaves=12,
)
poses = st.lists(st.floats(-1, 1) | values, min_size=0, max_size=4)


def _sometimes(keys: tuple[str, ...], value_of, required=None) -> st.SearchStrategy[dict]:
    """Mappings with some of `keys` (and those of `required`), each with a value from
    value_of(key), and now and then a stray key."""
    fields = {k: value_of(k) for k in keys}
    plain = st.fixed_dictionaries(required or {}, optional=fields)
    stray = st.fixed_dictionaries(required or {}, optional=fields | {"stray": values})
    return st.one_of(plain, plain, plain, stray)


def _object_value(key: str) -> st.SearchStrategy:
    return {
        "params": st.dictionaries(
            st.sampled_from(["size", "unit", "label", "solid", "dims", "width", "post"]),
            scalars,
            max_size=3,
        )
        | values,
        "perception": _sometimes(PERCEPTION_KEYS, lambda _: values) | values,
        "orientation": st.lists(st.floats(-2, 2), min_size=4, max_size=4) | values,
    }.get(key, values)


_FILES = {
    "scad": st.sampled_from(["m.scad", "m.scad", "block.stl", "nothere.scad"]),
    "mesh": st.sampled_from(
        ["block.stl", "block.stl", "m.scad", "nothere.stl", "x" * 5000 + ".stl"]
    ),
    "capture": st.sampled_from(["cloud.pcd", "cloud.pcd", "nothere.pcd"]),
}
# Mostly one file of one kind, as a scene has; now and then any of the keys.
terrain_objects = st.one_of(
    *(_sometimes(OBJECT_KEYS[3:], _object_value, {kind: files}) for kind, files in _FILES.items()),
    _sometimes(OBJECT_KEYS, lambda k: _FILES[k] | values if k in _FILES else _object_value(k)),
)


def _scene_value(key: str) -> st.SearchStrategy:
    return {
        "terrain": st.lists(terrain_objects, max_size=3)
        | st.lists(terrain_objects | values, max_size=3)
        | values,
        "robot": st.fixed_dictionaries({}, optional={"start": poses}) | values,
        "goal": poses,
        "seed": st.integers(-5, 2**32) | values,
        "ground": st.floats(-1, 1) | values,
        "bounds": st.lists(st.lists(st.floats(-2, 2), min_size=2, max_size=2), max_size=2) | values,
        "planner": _sometimes(CONFIG_KEYS, lambda _: values) | values,
        "sim": _sometimes(CONFIG_KEYS, lambda _: values) | values,
        "driver": _sometimes(CONFIG_KEYS, lambda _: values) | values,
    }.get(key, values)


scenes = _sometimes(SCENE_KEYS[2:], _scene_value, {"terrain": _scene_value("terrain")})

# Pieces of YAML syntax, so random text reaches the parser's corners: anchors and aliases,
# tags, flow collections, merges, block scalars, documents and directives.
yaml_pieces = st.lists(
    st.sampled_from(
        [
            "terrain:",
            "\n",
            "  ",
            "- ",
            "mesh: block.stl",
            "&a ",
            "*a",
            "<<: *a",
            "[",
            "]",
            "{",
            "}",
            ", ",
            ": ",
            "? ",
            "!!int ",
            "!!float ",
            "!!binary ",
            "!!python/object ",
            "!!set ",
            "|\n",
            ">\n",
            "---\n",
            "...\n",
            "%YAML 1.1\n",
            "1e6",
            "0x1F",
            "1:30",
            "2001-02-30",
            "'",
            '"',
            "#",
            "\t",
            "\x00",
            "\ufeff",
            "seed: ",
            "planner: ",
            "ground: ",
            "9" * 5000,
        ]
    )
    | st.text(max_size=6),
    max_size=40,
).map("".join)


def _write(folder: Path, text: str | bytes) -> Path:
    path = folder / "scene.yaml"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
    return path


def _loads_or_refuses(path: Path) -> None:
    try:
        scene = load_scene(path)
    except SceneError as exc:
        message = str(exc)
        assert message.startswith(str(path)), message
        assert len(message) < 3000, f"{len(message)} characters of error"
    else:
        assert isinstance(scene, Scene)


@given(data=scenes)
def test_a_scene_of_any_values_loads_or_is_refused_with_a_scene_error(folder, data):
    _loads_or_refuses(_write(folder, yaml.safe_dump(data, allow_unicode=True)))


@given(text=yaml_pieces | st.text(max_size=200))
def test_any_text_as_a_scene_file_loads_or_is_refused_with_a_scene_error(folder, text):
    _loads_or_refuses(_write(folder, text))


@given(raw=st.binary(max_size=200))
def test_any_bytes_as_a_scene_file_load_or_are_refused_with_a_scene_error(folder, raw):
    _loads_or_refuses(_write(folder, raw))


@given(text=yaml_pieces)
def test_load_yaml_reads_any_text_or_raises_its_error(text):
    try:
        load_yaml(text, "f.yaml", SceneError)
    except SceneError as exc:
        assert str(exc).startswith("f.yaml"), str(exc)
        assert len(str(exc)) < 1000


@pytest.mark.slow
@given(depth=st.integers(1, 3000), width=st.integers(1, 12))
def test_nesting_and_aliases_are_bounded_however_deep_or_wide(depth, width):
    nested = "a: " + "[" * depth + "]" * depth
    laughs = ["r0: &r0 [x, x]"] + [
        f"r{i}: &r{i} [{', '.join([f'*r{i - 1}'] * width)}]" for i in range(1, depth % 40 + 2)
    ]
    for text in (nested, "\n".join(laughs)):
        try:
            data = load_yaml(text, "f.yaml", SceneError)
        except SceneError as exc:
            assert any(w in str(exc) for w in ("levels deep", "values, counting each alias"))
        else:
            assert len(short_repr(data)) <= 100


def test_a_file_past_the_size_limit_is_refused_unread(folder):
    path = _write(folder, "# padding\n" * (MAX_YAML_BYTES // 10 + 1))
    limit = rf"too large for a YAML settings file \(at most {MAX_YAML_BYTES}"
    with pytest.raises(SceneError, match=limit):
        load_scene(path)
