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
from tcloth.render import Renderer
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
