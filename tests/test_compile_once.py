"""Compile once (tcloth/contact/warm.py): a simulator compiles the kernels its contact
stage may need when it is built, so that no frame after the first stalls on a compile
when contact starts (the proximity list's first rebuild at a step's end, the guard's
planes and checks)."""
import pytest

import tcloth

CLOTH = {"mass": 0.1, "structural": (400.0, 0.05), "shear": (80.0, 0.02),
         "flexion": (10.0, 0.005), "pinned": []}


@pytest.mark.parametrize("batch", [True, False])
def test_two_cloths_landing_compile_nothing_after_the_first_frame(batch):
    """Two 6 x 6 cloths 4 cm apart fall onto the ground; the lower one lands in the sixth
    frame of 25 ms, the upper one on it: the cloths' own pairs come within the proximity
    list's reach only then. After the first frame nothing compiles
    (tcloth.runtime.compilations), whether the steps run in batches or from Python."""
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(6, 6), size=(0.3, 0.3), center=(0, 0.1, 0), plane="xz",
                    **CLOTH)
    scene.add_cloth(resolution=(6, 6), size=(0.3, 0.3), center=(0.02, 0.14, 0.02),
                    plane="xz", **CLOTH)
    scene.add_plane(friction=0.3)
    scene.set_self_collision(thickness=0.01)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=5e-4, batch=batch)
    sim.step(50)
    sim.positions()
    first = sim.contact_stats()
    before = tcloth.runtime.compilations()
    assert first["candidates"] == 0
    for _ in range(8):
        sim.step(50)
        sim.positions()
    stats = sim.contact_stats()
    assert stats["candidates"] > 100                 # the layers met
    assert stats["rebuilds"] > first["rebuilds"] + 2
    assert tcloth.runtime.compilations() == before
