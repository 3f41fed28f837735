"""Every scene script's positions after 100 steps equal those stored in
``tests/data/scene_positions.npz`` (``python tools/scene_snapshot.py`` writes it), bit for
bit: float32 on the CPU, each scene with its CONFIG integrator and dt. A change that
alters the arithmetic (another order of a sum, a fused loop) shows here first; rewrite the
snapshot only after checking that the new numbers are right, and say so in the commit."""
import os
import sys

import numpy as np
import pytest

import tcloth

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tools"))
from scene_snapshot import snapshot  # noqa: E402


@pytest.fixture(scope="module")
def positions():
    tcloth.init(arch="cpu", precision="f32")
    return snapshot(100)


def test_every_scene_script_is_unchanged_after_100_steps(positions):
    stored = np.load(os.path.join(HERE, "data", "scene_positions.npz"))
    assert sorted(stored.files) == sorted(positions)
    for name, x in positions.items():
        assert np.array_equal(x, stored[name]), (name, np.abs(x - stored[name]).max())
