"""Compile once (tcloth/contact/warm.py): a simulator compiles the kernels its contact
stage may need when it is built (``compile_ahead``, a user's default), so that no frame after the first stalls on a compile
when contact starts (the proximity list's first rebuild at a step's end, the guard's
planes and checks)."""
import numpy as np
import pytest
import taichi as ti

import tcloth

CLOTH = {"mass": 0.1, "structural": (400.0, 0.05), "shear": (80.0, 0.02),
         "flexion": (10.0, 0.005), "pinned": []}


def landing(batch, compile_ahead):
    """(compilations after the first frame, positions, first frame's and last contact
    stats) of two 6 x 6 cloths 4 cm apart falling onto the ground in 9 frames of 25 ms."""
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(6, 6), size=(0.3, 0.3), center=(0, 0.1, 0), plane="xz",
                    **CLOTH)
    scene.add_cloth(resolution=(6, 6), size=(0.3, 0.3), center=(0.02, 0.14, 0.02),
                    plane="xz", **CLOTH)
    scene.add_plane(friction=0.3)
    scene.set_self_collision(thickness=0.01)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=5e-4, batch=batch,
                           compile_ahead=compile_ahead)
    sim.step(50)
    sim.positions()
    first = sim.contact_stats()
    before = tcloth.runtime.compilations()
    for _ in range(8):
        sim.step(50)
        sim.positions()
    return tcloth.runtime.compilations() - before, sim.positions(), first, sim.contact_stats()


@pytest.mark.slow
@pytest.mark.parametrize("batch", [True, False])
def test_two_cloths_landing_compile_nothing_after_the_first_frame(batch):
    """The lower cloth lands in the sixth frame, the upper one on it: the cloths' own
    pairs come within the proximity list's reach only then. After the first frame nothing
    compiles (tcloth.runtime.compilations), whether the steps run in batches or from
    Python."""
    late, _, first, stats = landing(batch, True)
    assert first["candidates"] == 0
    assert stats["candidates"] > 100                 # the layers met
    assert stats["rebuilds"] > first["rebuilds"] + 2
    assert late == 0


@pytest.mark.slow
def test_compiled_at_first_use_the_same_run_compiles_late_and_ends_the_same():
    """compile_ahead=False (the tests' default): the same landing compiles kernels in
    the later frames, and ends at the same positions, bit for bit."""
    late, x, _, _ = landing(True, False)
    assert late > 0
    assert np.array_equal(x, landing(True, True)[1])


def test_compile_ahead_is_read_from_the_environment(monkeypatch):
    monkeypatch.setenv("TCLOTH_COMPILE_AHEAD", "1")
    assert tcloth.runtime.compile_ahead(None) is True
    assert tcloth.runtime.compile_ahead(False) is False
    monkeypatch.setenv("TCLOTH_COMPILE_AHEAD", "yes")
    with pytest.raises(tcloth.SceneError, match="TCLOTH_COMPILE_AHEAD must be 0 or 1"):
        tcloth.runtime.compile_ahead(None)
    with pytest.raises(tcloth.SceneError, match="compile_ahead must be True, False or None"):
        tcloth.runtime.compile_ahead("on")


@pytest.mark.slow
def test_quick_compile_gives_the_shipped_numbers_bit_for_bit():
    """``tcloth.init(quick_compile=True)`` (the test suite's setting) turns Taichi's
    control-flow-graph optimisation off, and two cloths landing on each other and the
    ground, batched, their pairs listed by the contact stage, end where the shipped setting ends
    them, bit for bit."""
    runs = []
    for quick in (False, True):
        tcloth.init(arch="cpu", quick_compile=quick)
        assert ti.lang.impl.current_cfg().cfg_optimization is not quick
        _, x, _, stats = landing(True, False)
        assert stats["candidates"] > 0 and stats["rebuilds"] > 1, stats
        runs.append(x)
    assert np.array_equal(runs[0], runs[1])


def test_quick_compile_is_read_from_the_environment(monkeypatch):
    monkeypatch.setenv("TCLOTH_QUICK_COMPILE", "maybe")
    with pytest.raises(tcloth.SceneError, match="TCLOTH_QUICK_COMPILE must be 0 or 1"):
        tcloth.init(arch="cpu")
    with pytest.raises(tcloth.SceneError, match="quick_compile must be True, False or None"):
        tcloth.init(arch="cpu", quick_compile="yes")
