"""The USD text layer of one particle frame (core/usd_points.py): every float32 written exactly,
the primvar layout Blender's reader takes, and clear errors. Reading the files back in Blender
is tested in tests/blender/test_native_points.py."""
from __future__ import annotations

import re

import numpy as np
import pytest

from physanim.core import usd_points


def _frame(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    # float32 values of every magnitude, the extremes and signed zeros included
    wild = (rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-30, 30, (n, 3))).astype(np.float32)
    wild[0] = [np.finfo(np.float32).max, np.finfo(np.float32).tiny, -0.0]
    return {"id": np.arange(n, dtype=np.int32) * 997, "position": wild,
            "velocity": rng.standard_normal((n, 3)).astype(np.float32),
            "age": rng.random(n, dtype=np.float32) * 90.0,
            "size": rng.random(n, dtype=np.float32) * 0.1,
            "color": rng.random((n, 4), dtype=np.float32),
            "instance_rotation": rng.random((n, 3), dtype=np.float32)}


def _array(text: str, key: str) -> np.ndarray:
    """The numbers of one attribute, parsed back as float32."""
    match = re.search(re.escape(key) + r" = \[([^\]]*)\]", text)
    assert match, key
    numbers = re.findall(r"[-+0-9.eE]+|inf|nan", match.group(1))
    return np.array([float(x) for x in numbers], np.float64).astype(np.float32)


def test_every_float32_is_written_exactly():
    arrays = _frame(200)
    text = usd_points.points_usda(arrays, frame=17)
    assert text.startswith("#usda 1.0")
    assert "startTimeCode = 17" in text and 'def Points "particles"' in text
    got = _array(text, "point3f[] points").reshape(-1, 3)
    np.testing.assert_array_equal(got.view(np.uint32), arrays["position"].view(np.uint32))
    np.testing.assert_array_equal(_array(text, "velocities").reshape(-1, 3), arrays["velocity"])
    np.testing.assert_array_equal(_array(text, "widths"), 2.0 * arrays["size"])
    assert "primvars:size" not in text and "primvars:radius" not in text  # widths only
    np.testing.assert_array_equal(_array(text, "primvars:age"), arrays["age"])
    np.testing.assert_array_equal(_array(text, "primvars:physanim_id"),
                                  arrays["id"].astype(np.float32))
    for k in range(4):
        np.testing.assert_array_equal(_array(text, f"primvars:color_{k}"), arrays["color"][:, k])


def test_primvars_are_floats_in_name_order_and_id_is_renamed():
    """Blender 4.2 drops a primvar type it cannot read and every primvar after it (in name
    order), and 4.2/4.5 point clouds reserve "id" for integers: only float[] primvars, never
    one named id."""
    text = usd_points.points_usda(_frame(5), frame=1)
    declared = re.findall(r"^    (\S+) primvars:(\S+) =", text, flags=re.M)
    assert {kind for kind, _ in declared} == {"float[]"}
    names = [name for _, name in declared]
    assert names == sorted(names)
    assert "id" not in names and "physanim_id" in names
    assert {"instance_rotation_0", "instance_rotation_1", "instance_rotation_2"} <= set(names)
    assert text.count('interpolation = "vertex"') == len(names)


def test_layout_names_each_attribute_and_its_primvars():
    layout = usd_points.attribute_layout(_frame(3))
    assert layout["id"] == ('INT', ["physanim_id"])
    assert layout["age"] == ('FLOAT', ["age"])
    assert layout["size"] == ('FLOAT', ["radius"])  # Blender's reader: half the widths
    assert layout["color"] == ('FLOAT_COLOR', ["color_0", "color_1", "color_2", "color_3"])
    assert layout["instance_rotation"][0] == 'FLOAT_VECTOR'
    assert "position" not in layout and "velocity" not in layout


def test_an_empty_frame_is_a_valid_layer():
    arrays = {k: v[:0] for k, v in _frame(4).items()}
    text = usd_points.points_usda(arrays, frame=3)
    assert "point3f[] points = []" in text and "float[] primvars:age = []" in text


@pytest.mark.parametrize("change, words", [
    (lambda a: a["position"].__setitem__((2, 1), np.nan), "non-finite"),
    (lambda a: a["color"].__setitem__((0, 3), np.inf), "non-finite"),
    (lambda a: a.__setitem__("id", a["id"] + 2 ** 24), "16,777,216"),
    (lambda a: a.__setitem__("age", a["age"][:-1]), "rows for"),
    (lambda a: a.__setitem__("weights", np.zeros((len(a["id"]), 2))), "shape"),
])
def test_bad_arrays_fail_with_the_reason(change, words):
    arrays = _frame(6)
    change(arrays)
    with pytest.raises(ValueError, match=words):
        usd_points.points_usda(arrays, frame=1)


def test_write_puts_the_frame_in_the_file_name(tmp_path):
    path = tmp_path / usd_points.frame_file_name(42)
    usd_points.write_points_usda(path, _frame(3), 42)
    assert path.name == "points_000042.usda"
    assert "startTimeCode = 42" in path.read_text()
