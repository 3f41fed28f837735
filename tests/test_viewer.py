"""The sandbox window: a screenshot under Xvfb with a software Vulkan driver against the
off-screen renderer's image of the same state, and the one-line error without a display."""
import ctypes.util
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

import tcloth
from tcloth.render.render import Renderer
from tcloth.viewer import PANEL_WIDTH, DisplayError, check_vulkan

from conftest import SCENES, scene_module

SCRIPT = os.path.join(SCENES, "hanging_cloth.py")


def window_missing():
    """Why no window can be tested here, or None."""
    if shutil.which("xvfb-run") is None:
        return "xvfb-run is not installed (apt-get install xvfb; .ci/run installs it)"
    try:
        check_vulkan()
    except DisplayError as e:
        return str(e)
    return None


@pytest.mark.slow
@pytest.mark.skipif(window_missing() is not None, reason=str(window_missing()))
def test_window_shows_the_cloth_where_the_offscreen_renderer_does(tmp_path):
    """30 frames in the window under Xvfb, then its image: the cloth covers the same
    pixels as in the off-screen renderer's image of the same state (same camera), right
    of the panel."""
    width, height, frames = 640, 400, 30
    shot = tmp_path / "window.png"
    run = subprocess.run(["xvfb-run", "-a", sys.executable, "-m", "tcloth", "view", SCRIPT,
                          "--frames", str(frames), "--screenshot", str(shot),
                          "--width", str(width), "--height", str(height)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    from PIL import Image
    image = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert image.shape == (height, width, 3)

    tcloth.init(arch="cpu")
    module = scene_module("hanging_cloth")
    cfg = module.CONFIG
    sim = tcloth.Simulator(module.build(), cfg["integrator"], dt=cfg["dt"])
    sim.step(frames * cfg["steps_per_frame"])
    renderer = Renderer(sim, width, height, cfg["camera"], supersample=1, ground=-0.2)
    renderer.render()
    expected = renderer.ids() < renderer.tri_count
    seen = image.max(2) - image.min(2) > 60      # the cloth's colours are the saturated ones
    right = np.arange(width)[None, :] > PANEL_WIDTH * width + 2
    expected, seen = expected & right, seen & right
    assert expected.sum() > 0.02 * expected.size
    overlap = (expected & seen).sum() / (expected | seen).sum()
    assert overlap > 0.95, overlap


@pytest.mark.slow_cases("box")
@pytest.mark.parametrize("kind", ["box", "capsule", "sphere"])
def test_the_window_draws_resting_cloth_out_of_its_collider(kind):
    """The window draws each collider's mesh, whose vertices lie on its surface (so the
    mesh lies inside it), and the cloth where ``DrawnCloth`` puts it, as the off-screen
    renderer does: for a coarse cloth wrapped round a rod, a capsule or a sphere at the
    thickness or a quarter of it (``test_render.wrapped_cloth``), no point of the drawn
    cloth is inside the collider (the independent signed distance of test_colliders, at
    45 points a triangle), so no face of the collider's mesh can show through it."""
    from test_colliders import numpy_sdf
    from test_render import wrapped_cloth
    from tcloth.render.drawables import DrawnCloth
    from tcloth.viewer.meshes import collider_mesh
    tcloth.init(arch="cpu")
    sim = tcloth.Simulator(wrapped_cloth(kind, 0.005))
    collider = sim.scene.colliders[0]
    mesh = collider_mesh(collider, 0.0, 1.0, 0.1)[0]
    assert max(numpy_sdf(collider, v)[0] for v in mesh) < 1e-9
    triangles = sim.scene.cloths[0].triangles
    drawn = DrawnCloth(sim.model.colliders, triangles, sim.scene.num_particles)
    u, v = np.meshgrid(np.arange(9), np.arange(9), indexing="ij")
    keep = u + v <= 8
    weights = np.stack([8 - u[keep] - v[keep], u[keep], v[keep]], 1) / 8.0
    for rest in (0.005, 0.00125):
        x = wrapped_cloth(kind, rest).positions
        assert np.min([numpy_sdf(collider, p)[0] for p in x]) == pytest.approx(rest)
        sim.set_state(positions=x)
        y = drawn.update(sim.state.x, 0.0).to_numpy().astype(np.float64)
        points = np.einsum("sk,tkd->tsd", weights, y[triangles]).reshape(-1, 3)
        assert min(numpy_sdf(collider, p)[0] for p in points) > 0.0
        chords = np.einsum("sk,tkd->tsd", weights, x[triangles]).reshape(-1, 3)
        assert min(numpy_sdf(collider, p)[0] for p in chords) < -0.002   # they cut in


def test_drawn_cloth_on_a_flat_face_and_on_cloth_is_where_its_particles_are():
    """A cloth lying flat on a box's top face at the thickness and a second one 1.2 cm
    above it are drawn at their particles: flat triangles do not cut into a flat face."""
    from tcloth.render.drawables import DrawnCloth
    tcloth.init(arch="cpu")
    scene = tcloth.Scene(gravity=(0, 0, 0))
    for side, height in ((0.6, 0.055), (0.4, 0.067)):
        scene.add_cloth(resolution=(8, 8), size=(side, side), center=(0, height, 0),
                        structural=None, shear=None, flexion=None, pinned=[])
    scene.add_box((0, 0, 0), (0.5, 0.05, 0.5), thickness=0.005)
    sim = tcloth.Simulator(scene)
    triangles = np.concatenate([c.triangles for c in scene.cloths])
    drawn = DrawnCloth(sim.model.colliders, triangles, scene.num_particles)
    y = drawn.update(sim.state.x, 0.0).to_numpy()
    assert np.abs(y - scene.positions).max() < 1e-6


def test_no_display_is_one_line_and_exit_code_2():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    run = subprocess.run([sys.executable, "-m", "tcloth", "view", SCRIPT], env=env,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "no display" in lines[0] and "xvfb" in lines[0], run.stderr


def test_missing_vulkan_driver_is_named(monkeypatch):
    monkeypatch.delenv("VK_DRIVER_FILES", raising=False)
    monkeypatch.setenv("VK_ICD_FILENAMES", "/nonexistent/icd.json")
    missing = ("no Vulkan loader \\(libvulkan.so.1\\): apt-get install libvulkan1"
               if ctypes.util.find_library("vulkan") is None else
               "no Vulkan driver: apt-get install mesa-vulkan-drivers")
    with pytest.raises(DisplayError, match=missing):
        check_vulkan()
