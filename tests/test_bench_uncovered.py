"""bench/bench_uncovered.py: which uncovered truth a viewpoint could see, and square-on enough."""

from __future__ import annotations

import sys
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from bench_uncovered import seen_from_some_view  # noqa: E402

WALL = """
<mujoco><worldbody>
  <geom name="wall" type="box" pos="0 0 1" size="0.1 3 1"/>
  <geom name="screen" type="box" pos="1.5 -1.0 1" size="0.05 0.2 1"/>
</worldbody></mujoco>
"""


def test_a_view_square_on_counts_and_a_grazing_or_hidden_one_does_not() -> None:
    model = mujoco.MjModel.from_xml_string(WALL)
    point = np.array([[0.1, 0.0, 0.6]])  # on the wall's +x face
    normal = np.array([[1.0, 0.0, 0.0]])
    square_on = np.array([[2.0, 0.0, 0.35]])
    grazing = np.array([[0.6, 3.0, 0.35]])  # 80.5° off the normal
    behind = np.array([[-2.0, 0.0, 0.35]])  # the wall is in the way
    shaded = np.array([[2.5, -1.6, 0.35]])  # the screen is in the way
    for views, at_all, within in ((square_on, True, True), (grazing, True, False),
                                  (behind, False, False), (shaded, False, False)):
        seen, square = seen_from_some_view(model, point, normal, views, 5.0, 34.08, 80.0)
        assert (seen[0], square[0]) == (at_all, within), views
    # out of the vertical FoV: 2.5 m above a camera 0.5 m away
    high = np.array([[0.1, 0.0, 2.9]])
    seen, _ = seen_from_some_view(model, high, normal, np.array([[0.6, 0.0, 0.35]]), 5.0,
                                  34.08, 80.0)
    assert not seen[0]
