"""Renderer, recording and the command line."""
import glob
import os
import subprocess
import sys
import threading

import imageio_ffmpeg
import numpy as np
import pytest

import tcloth
from tcloth import Camera
from tcloth.app.script import load_script
from tcloth.render.framing import ground_and_checker
from tcloth.render.raster import COLLIDER_ID
from tcloth.render.render import LIGHT_DIR

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RED, GREEN, BLUE = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def project(camera, points, width, height):
    """Independent pinhole projection to pixel (col, row)."""
    d = points - camera.eye
    z = d @ camera.forward
    t = np.tan(np.radians(camera.fov) / 2)
    col = (d @ camera.right / (z * t * width / height) + 1) * width / 2 - 0.5
    row = (1 - d @ camera.up / (z * t)) * height / 2 - 0.5
    return col, row


def two_quads():
    """Two overlapping square cloths facing +z; the nearer (z = 0.5) is shifted right."""
    scene = tcloth.Scene(gravity=(0, 0, 0))
    near = scene.add_cloth(resolution=(2, 2), size=(1, 1), center=(0.3, 0, 0.5), plane="xy",
                           structural=None, shear=None, flexion=None, pinned=[])
    far = scene.add_cloth(resolution=(2, 2), size=(1, 1), center=(-0.3, 0, 0.0), plane="xy",
                          structural=None, shear=None, flexion=None, pinned=[])
    return scene, near, far


def render_two_quads():
    scene, near, far = two_quads()
    sim = tcloth.Simulator(scene)
    r = tcloth.Renderer(sim, 96, 64, camera={"eye": (0, 0, 4), "target": (0, 0, 0)},
                        supersample=1, ground=False, shadows=False,
                        cloth_colours=[(RED, BLUE), (GREEN, BLUE)])
    return r, r.render()


def test_depth_test_shows_the_nearer_triangle_and_is_bit_identical(f32):
    r, img = render_two_quads()
    # pixel columns: only far (left), overlap, only near (right); row through the middle
    cam = r.camera
    cols, _ = project(cam, np.array([[-0.5, 0, 0], [0.2, 0, 0], [0.75, 0, 0]]), 96, 64)
    row = 32
    left, mid, right = (img[row, int(round(c))] for c in cols)
    assert left[1] > 3 * left[0] and mid[0] > 3 * mid[1] and right[0] > 3 * right[1]
    ids = r.ids()
    assert ids[row, int(round(cols[1]))] in (0, 1)          # a triangle of the near cloth
    assert ids[row, int(round(cols[0]))] in (2, 3)
    for _ in range(2):
        again = render_two_quads()[1]
        assert np.array_equal(img, again)


def test_triangles_that_share_edges_leave_no_sample_between_them(f32):
    """A flat square cloth whose inner particles are jittered within its plane, seen at a
    slant: its triangles tile the square exactly, so every sample whose ray meets the
    plane inside the square (an independent ray-plane test, half a sample's width in
    from its edges) sees a triangle of it, and none outside it does."""
    scene = tcloth.Scene(gravity=(0, 0, 0))
    cloth = scene.add_cloth(resolution=(24, 24), size=(1, 1), center=(0, 0, 0), plane="xz",
                            structural=None, shear=None, flexion=None, pinned=[])
    x = scene.positions.copy()
    inner = cloth.particles[1:-1, 1:-1].ravel()
    x[inner, ::2] += np.random.default_rng(3).uniform(-0.012, 0.012, (len(inner), 2))
    sim = tcloth.Simulator(scene)
    sim.set_state(positions=x)
    cam = Camera((0.7, 0.9, 1.3), (0.05, 0.0, 0.0), fov=50.0)
    width, height = 160, 120
    r = tcloth.Renderer(sim, width, height, camera=cam, supersample=1, ground=False,
                        shadows=False)
    r.render()
    cloth_seen = r.ids() < r.tri_count
    col, row = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    t = np.tan(np.radians(cam.fov) / 2)
    d = (cam.forward + ((2 * col / width - 1) * t * width / height)[..., None] * cam.right
         + ((1 - 2 * row / height) * t)[..., None] * cam.up)
    hit = cam.eye + (-cam.eye[1] / np.minimum(d[..., 1], -1e-9))[..., None] * d
    # half the distance to the next samples' hits
    margin = 0.5 * np.linalg.norm(np.gradient(hit, axis=(0, 1)), axis=(0, -1))
    edge = np.abs(hit[..., [0, 2]]).max(-1)
    inside, outside = edge < 0.5 - margin, edge > 0.5 + margin
    assert cloth_seen[inside].all() and not cloth_seen[outside].any()
    assert inside.sum() > 0.1 * width * height


@pytest.mark.parametrize("from_above", [True, False])
def test_cloth_covers_its_projected_box_and_shows_the_side_facing_the_camera(f32, from_above):
    scene = tcloth.Scene()
    cloth = scene.add_cloth(resolution=(9, 7), size=(1.0, 0.7), center=(0.1, 1.0, -0.2))
    sim = tcloth.Simulator(scene)
    eye = (0.4, 2.8, 1.4) if from_above else (0.4, -0.8, 1.4)
    cam = Camera(eye, (0.1, 1.0, -0.2), fov=35.0)
    r = tcloth.Renderer(sim, 160, 120, camera=cam, supersample=1, ground=False, shadows=False,
                        cloth_colours=[(RED, BLUE)])
    img = r.render()
    mask = r.ids() < COLLIDER_ID
    rows, cols = np.nonzero(mask)
    corners = scene.positions[cloth.particles[[0, 0, -1, -1], [0, -1, 0, -1]]]
    pc, pr = project(cam, corners, 160, 120)
    assert abs(cols.min() - pc.min()) <= 1.5 and abs(cols.max() - pc.max()) <= 1.5
    assert abs(rows.min() - pr.min()) <= 1.5 and abs(rows.max() - pr.max()) <= 1.5
    covered = img[mask].astype(int)
    if from_above:       # the front (normal +y) faces the camera: red
        assert np.all(covered[:, 0] > covered[:, 2])
    else:
        assert np.all(covered[:, 2] > covered[:, 0])


def test_record_writes_mp4_with_requested_frames_and_size(f32, tmp_path):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(8, 8))
    sim = tcloth.Simulator(scene, dt=5e-4)
    out = str(tmp_path / "clip.mp4")
    stats = tcloth.record(sim, out, frames=7, steps_per_frame=3, width=96, height=64,
                          progress=False)
    assert stats["frames"] == 7 and sim.num_steps == 18
    reader = imageio_ffmpeg.read_frames(out)
    meta = next(reader)
    frames = list(reader)
    assert meta["size"] == (96, 64) and len(frames) == 7
    assert all(len(f) == 96 * 64 * 3 for f in frames)
    assert not glob.glob(str(tmp_path / "*partial*"))


def writer_threads():
    return [t for t in threading.enumerate() if t.name == "tcloth frame writer"]


def test_an_encoder_error_ends_the_run_and_leaves_nothing_partial(f32, tmp_path, monkeypatch):
    """Frames are encoded on a thread of their own: its error (a full disk at the third
    frame) comes back to the caller, the run stops, the thread ends and no partial
    output is left."""
    from tcloth.render import video
    written = []

    def write_png(path, image):
        if len(written) == 2:
            raise OSError("no space left on device")
        written.append(path)
    monkeypatch.setattr(video, "write_png", write_png)
    sim = tcloth.Simulator(small_scene(), dt=1e-3)
    with pytest.raises(OSError, match="no space left"):
        tcloth.record(sim, str(tmp_path / "frames"), frames=40, steps_per_frame=1, width=32,
                      height=24, progress=False)
    assert len(written) == 2 and sim.num_steps < 39
    assert os.listdir(tmp_path) == [] and not writer_threads()


def test_ctrl_c_keeps_the_frames_made_so_far(f32, tmp_path, monkeypatch):
    """Ctrl-C during the fifth frame's steps: the four frames before are written out
    whole under the output's name, the interrupt raised again saying so."""
    sim = tcloth.Simulator(small_scene(), dt=1e-3)
    step = sim.step

    def interrupted(n=1):
        if sim.num_steps == 3:
            raise KeyboardInterrupt
        step(n)
    monkeypatch.setattr(sim, "step", interrupted)
    with pytest.raises(KeyboardInterrupt, match="Kept 4 good frames"):
        tcloth.record(sim, str(tmp_path / "frames"), frames=10, steps_per_frame=1, width=32,
                      height=24, progress=False)
    assert sorted(os.listdir(tmp_path / "frames")) == [f"frame_0000{k}.png" for k in range(4)]
    assert os.listdir(tmp_path) == ["frames"] and not writer_threads()


def test_the_command_line_says_what_ctrl_c_kept(capsys):
    def interrupted():
        raise KeyboardInterrupt("Interrupted. Kept 4 good frames in out/x.mp4.")
    assert tcloth.app.cli._guarded(interrupted, verbose=False) == 130
    assert capsys.readouterr().err == "tcloth: Interrupted. Kept 4 good frames in out/x.mp4.\n"


def small_scene():
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4))
    return scene


def test_record_png_folder_and_odd_size_refused_for_mp4(f32, tmp_path):
    scene = tcloth.Scene()
    scene.add_rope((0, 1, 0), (1, 1, 0), 5, 0.1, 50.0)
    sim = tcloth.Simulator(scene, dt=1e-3)
    tcloth.record(sim, str(tmp_path / "frames"), frames=3, steps_per_frame=2, width=64,
                  height=48, progress=False)
    names = sorted(os.listdir(tmp_path / "frames"))
    assert names == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    with open(tmp_path / "frames" / names[0], "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(tcloth.SceneError, match="even width"):
        tcloth.record(sim, str(tmp_path / "odd.mp4"), frames=2, width=63, height=48,
                      progress=False)


def run_cli(*args, cwd=ROOT, env=None):
    """``python -m tcloth ARGS`` with the environment updated by ``env``."""
    return subprocess.run([sys.executable, "-m", "tcloth", *args], cwd=cwd,
                          env={**os.environ, **(env or {})}, capture_output=True, text=True,
                          timeout=600)


SCENES = sorted(glob.glob(os.path.join(ROOT, "scenes", "*.py")))


@pytest.mark.slow_cases(
    "cloth_on_box.py",
    "cloth_on_sphere.py",
    "cloth_pile.py",
    "curtain.py",
    "drape.py",
    "fold.py",
    "negative_examples.py",
    "tablecloth.py",
    "table.py",
    "turntable.py",
    "breathing.py",
    "incline.py",
    "strain_limiting.py",
    "sphere_through_cloth.py",
    "flag.py",
    "tearing.py",
    "garment.py",
)
@pytest.mark.parametrize("script", SCENES, ids=[os.path.basename(s) for s in SCENES])
def test_every_scene_script_renders_headless(script, tmp_path, request):
    """Each shipped scene renders its first 30 frames (a second of video) as it ships:
    its own integrator, dt and steps a frame, small images; the quick set's scenes with
    Taichi's optimisation on, as the command line ships."""
    out = tmp_path / "frames"
    quick = not any(mark.name == "slow" for mark in request.node.iter_markers())
    res = run_cli("render", script, "--out", str(out), "--frames", "30", "--width", "64",
                  "--height", "48", "--supersample", "1", "--quiet",
                  env={"TCLOTH_QUICK_COMPILE": "0"} if quick else None)
    assert res.returncode == 0, res.stderr
    assert len(os.listdir(out)) == 30


def test_cli_list_describes_scenes():
    res = run_cli("list")
    assert res.returncode == 0
    header, *rows = res.stdout.strip().splitlines()
    assert header.split()[:3] == ["script", "integrator", "dt"] and len(rows) == len(SCENES)
    # each scene's integrator, dt and particles as its script builds them
    table = [row for row in rows if row.startswith("table.py")][0].split()
    module, cfg = load_script(os.path.join(ROOT, "scenes", "table.py"))
    assert table[1] == cfg["integrator"] and table[4] == str(module.build().num_particles)
    assert table[3] == str(cfg["steps_per_frame"])


@pytest.mark.parametrize("script", SCENES, ids=[os.path.basename(s) for s in SCENES])
def test_each_scene_argues_its_defaults(script):
    """A scene's docstring has a paragraph that begins "Defaults:" and names the
    integrator its CONFIG steps with, so that its choice of integrator and step is argued
    where the scene is."""
    module, cfg = load_script(script)
    paragraphs = [" ".join(p.split()) for p in module.__doc__.split("\n\n")]
    defaults = [p for p in paragraphs if p.startswith("Defaults:")]
    assert len(defaults) == 1, paragraphs
    name = {"symplectic_euler": "symplectic Euler", "backward_euler": "backward Euler",
            "verlet": "Verlet", "projective": "projective dynamics", "xpbd": "XPBD",
            "vbd": "VBD"}[cfg["integrator"]]
    assert name in defaults[0], defaults[0]


def test_cli_errors_are_clear_with_exit_code_2(tmp_path):
    res = run_cli("render", "no/such/scene.py")
    assert res.returncode == 2 and "no/such/scene.py" in res.stderr and "does not exist" in res.stderr
    assert "Traceback" not in res.stderr
    nobuild = tmp_path / "nobuild.py"
    nobuild.write_text("CONFIG = {}\n")
    res = run_cli("render", str(nobuild))
    assert res.returncode == 2 and "build" in res.stderr
    raising = tmp_path / "raising.py"
    raising.write_text("def build():\n    raise RuntimeError('boom')\n")
    res = run_cli("render", str(raising), "--out", str(tmp_path / "x"))
    assert res.returncode == 2 and "boom" in res.stderr and "Traceback" not in res.stderr
    res = run_cli("render", str(raising), "--out", str(tmp_path / "x"), "--verbose")
    assert "Traceback" in res.stderr
    blocked = tmp_path / "file"
    blocked.write_text("")
    res = run_cli("render", os.path.join(ROOT, "scenes", "rope.py"), "--out",
                  str(blocked / "sub" / "out.mp4"))
    assert res.returncode == 2 and "output folder" in res.stderr


# -- the ground, scripts without CONFIG, --set, --arch ------------------------------------
def readme_example():
    """The Python block under "A scene in a few lines" in README.md."""
    with open(os.path.join(ROOT, "README.md")) as f:
        text = f.read()
    section = text.split("## A scene in a few lines", 1)[1]
    return section.split("```python", 1)[1].split("```", 1)[0]


def test_the_readme_example_shows_what_it_says(f32, monkeypatch):
    """Its cloth swings onto its sphere (contact energy), and the ground is drawn below
    everything the cloth reaches, not through it (a ground at the cloth's start would
    hide the cloth's lower part and half the sphere)."""
    seen = {"contact": 0.0, "lowest": np.inf, "frames": 0}

    def record(sim, path, frames, steps_per_frame, **options):
        for _ in range(frames):
            sim.step(steps_per_frame)
            seen["contact"] = max(seen["contact"], sim.energy()["contact"])
            seen["lowest"] = min(seen["lowest"], sim.positions()[:, 1].min())
            seen["frames"] += 1
        seen["sim"] = sim
    monkeypatch.setattr(tcloth, "record", record)
    monkeypatch.setattr(tcloth, "init", lambda **kwargs: None)
    exec(readme_example(), {"__name__": "readme"})
    scene = seen["sim"].scene
    ground, _ = ground_and_checker(scene, None, np.sqrt(2.0))
    sphere = scene.colliders[0]
    assert seen["frames"] == 90 and seen["contact"] > 0.0
    assert ground < seen["lowest"] and ground < sphere["center"][1] - sphere["radius"]


def test_a_ground_is_drawn_only_below_what_can_reach_it():
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(6, 6), size=(1, 1), center=(0, 1, 0), pinned=[(0, 0)])
    ground, _ = ground_and_checker(scene, None, 1.0)
    # the far corner hangs at most its shortest spring path below the pin (1 m of
    # structural springs, or sqrt(2) m of shear ones: sqrt(2) * 1.25 stretched)
    assert ground < 1.0 - 1.25 * np.sqrt(2.0) + 1e-9
    free = tcloth.Scene()
    free.add_cloth(resolution=(6, 6), pinned=[])
    free.add_sphere((0, 0, 0), 0.3)
    assert ground_and_checker(free, None, 1.0)[0] is False
    free.add_plane()
    assert ground_and_checker(free, None, 1.0)[0] is False
    assert ground_and_checker(free, 0.25, 1.0)[0] == 0.25
    floating = tcloth.Scene(gravity=(0, 0, 0))
    floating.add_particles([[0, 1, 0], [0, 2, 0]])
    assert ground_and_checker(floating, None, 1.0)[0] < 1.0


CONFIGLESS = ("import tcloth\n"
              "def build(resolution=(32, 32)):\n"
              "    scene = tcloth.Scene(gravity=(0, -9.81, 0), air_drag=2e-4)\n"
              "    scene.add_cloth(resolution=resolution, size=(1, 1), center=(0, 1, 0),\n"
              "                    mass=0.2, structural=(400, 0.05), shear=(80, 0.02),\n"
              "                    flexion=(10, 0.005), pinned=[(0, 0), (resolution[0] - 1, 0)])\n"
              "    return scene\n")


@pytest.mark.slow
def test_a_script_without_config_gets_a_stable_real_time_step(f32, tmp_path):
    """The README's cloth as a script with no CONFIG (a fixed dt = 1e-3 is too large for
    it): the step from its springs is below symplectic Euler's limit, a frame is
    1/30 s of simulated time, and a second of it runs without blowing up; --dt alone
    keeps real time too."""
    script = tmp_path / "bare.py"
    script.write_text(CONFIGLESS)
    module, cfg = tcloth.app.script.load_script(str(script))
    scene = module.build()
    dt, steps = tcloth.app.script.timing(cfg, scene)
    assert dt < tcloth.scene.stability.explicit_dt_limit(scene)
    assert steps * dt == pytest.approx(1 / 30, rel=1e-12)
    tcloth.Simulator(scene, cfg["integrator"], dt=dt).step(30 * steps)
    assert tcloth.app.script.timing({**cfg, "dt": 1e-4}, scene) == (1e-4, 333)
    assert tcloth.app.script.timing({**cfg, "integrator": "backward_euler"}, scene)[1] == 4
    with pytest.raises(tcloth.InstabilityError):
        tcloth.Simulator(scene, "symplectic_euler", dt=1e-3, split=False).step(400)


@pytest.mark.slow
def test_cli_set_passes_build_parameters_and_names_unknown_ones(tmp_path):
    script = tmp_path / "bare.py"
    script.write_text(CONFIGLESS)
    meshes = tmp_path / "meshes"
    res = run_cli("render", str(script), "--out", str(tmp_path / "f"), "--frames", "2",
                  "--width", "32", "--height", "24", "--supersample", "1", "--quiet",
                  "--set", "resolution=[6,5]", "--meshes", str(meshes))
    assert res.returncode == 0, res.stderr
    assert "running on the CPU" in res.stderr
    with open(meshes / "frame_00000.obj") as f:
        assert sum(line.startswith("v ") for line in f) == 30
    res = run_cli("render", str(script), "--out", str(tmp_path / "g"), "--set", "size=2")
    assert res.returncode == 2 and "no build parameter 'size'" in res.stderr
    assert "resolution" in res.stderr and "Traceback" not in res.stderr
    res = run_cli("render", str(script), "--out", str(tmp_path / "g"), "--set", "resolution")
    assert res.returncode == 2 and "NAME=VALUE" in res.stderr


def test_a_gpu_asked_for_and_not_given_is_said():
    """Taichi falls back to the CPU without a word when no CUDA is there, and Vulkan may be
    a software driver on the CPU (lavapipe): tcloth warns in both cases."""
    try:
        with pytest.warns(tcloth.DeviceWarning, match="running on the CPU"):
            tcloth.init(arch="cuda")
        assert tcloth.runtime.cpu()
    except pytest.fail.Exception:
        assert not tcloth.runtime.cpu()        # a real CUDA device: nothing to say
    from tcloth.runtime.vulkan_probe import devices
    found = devices()
    if found and all(kind == "CPU" for _, kind in found):
        with pytest.warns(tcloth.DeviceWarning, match="software driver"):
            tcloth.init(arch="vulkan")
    tcloth.init(arch="cpu")


def test_cloth_resting_on_a_collider_hides_its_rim(f32):
    """A coarse cloth lying a thickness over a sphere: between its particles the flat
    triangles cut into the sphere, whose cap must not show through them. Seen from above,
    no pixel inside the cloth shows the collider."""
    scene = tcloth.Scene(gravity=(0, 0, 0))
    n, half, radius, thickness = 7, 0.2, 0.12, 0.005
    scene.add_cloth(resolution=(n, n), size=(2 * half, 2 * half), center=(0, 0, 0),
                    structural=None, shear=None, flexion=None, pinned=[])
    scene.add_sphere((0, 0, 0), radius, thickness=thickness)
    x = scene.positions.copy()
    r2 = x[:, 0] ** 2 + x[:, 2] ** 2
    x[:, 1] = np.sqrt(np.maximum((radius + thickness) ** 2 - r2, 0.0))
    sim = tcloth.Simulator(scene)
    sim.set_state(positions=x)
    r = tcloth.Renderer(sim, 120, 120, camera={"eye": (0, 2, 0.001), "target": (0, 0, 0),
                                               "fov": 20}, supersample=1, ground=False)
    r.render()
    ids = r.ids()
    col, row = project(r.camera, np.array([[-0.15, 0.1, -0.15], [0.15, 0.1, 0.15]]), 120, 120)
    inside = ids[int(min(row)):int(max(row)), int(min(col)):int(max(col))]
    assert (inside < r.tri_count).mean() > 0.99 and not (inside >= COLLIDER_ID).any()


@pytest.mark.slow
def test_a_cloth_over_a_cloth_resting_on_a_collider_stays_in_front(f32):
    """Two flat cloths on a box: the lower rests on it, the upper 1.2 cm higher, beyond
    the renderer's reach of a collider. Drawing cloth that rests on a collider nearer
    than it is (by half its longest edge, 6 cm here) put the lower cloth in front of the
    upper (cloth_pile's lower layers showed through); the collider drawn farther keeps
    the layers in their order. Seen from above, the upper cloth's pixels are its own."""
    scene = tcloth.Scene(gravity=(0, 0, 0))
    top, thickness = 0.05, 0.005
    lower = scene.add_cloth(resolution=(8, 8), size=(0.6, 0.6), center=(0, top + thickness, 0),
                            structural=None, shear=None, flexion=None, pinned=[])
    scene.add_cloth(resolution=(8, 8), size=(0.4, 0.4), center=(0, top + thickness + 0.012, 0),
                    structural=None, shear=None, flexion=None, pinned=[])
    scene.add_box((0, 0, 0), (0.5, top, 0.5), thickness=thickness)
    sim = tcloth.Simulator(scene)
    r = tcloth.Renderer(sim, 120, 120, camera={"eye": (0, 2, 0.6), "target": (0, 0, 0),
                                               "fov": 25}, supersample=1, ground=False)
    r.render()
    ids = r.ids()
    col, row = project(r.camera, np.array([[-0.15, 0.067, -0.15], [0.15, 0.067, 0.15]]),
                       120, 120)
    inside = ids[int(min(row)):int(max(row)), int(min(col)):int(max(col))]
    lower_triangles = len(lower.triangles)
    assert ((inside >= lower_triangles) & (inside < r.tri_count)).all()
    # and the lower cloth still hides the box where the upper one does not cover it
    col, row = project(r.camera, np.array([[0.22, 0.055, -0.05], [0.27, 0.055, 0.05]]),
                       120, 120)
    rim = ids[int(min(row)):int(max(row)), int(min(col)):int(max(col))]
    assert rim.size and (rim < lower_triangles).all()


WRAPPED = {   # collider and camera of each wrapped_cloth case
    "box": ((0.0, 0.02, 0.0), {"half_extents": (0.25, 0.02, 0.02)},
            {"eye": (0.1, 0.2, 0.35), "target": (0.0, 0.02, 0.0), "fov": 35}),
    "capsule": ((0.0, 0.06, 0.0), {"radius": 0.04, "half_height": 0.08,
                                   "rotation": [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]},
                {"eye": (0.25, 0.25, 0.35), "target": (0.05, 0.06, 0.0), "fov": 35}),
    "sphere": ((0.0, 0.08, 0.0), {"radius": 0.08},
               {"eye": (0.2, 0.3, 0.35), "target": (0.0, 0.08, 0.0), "fov": 35})}


def wrapped_cloth(kind, rest, thickness=0.005, rows=7, cols=8):
    """A scene with one collider and a coarse closed mesh cloth wrapped all round it, its
    particles ``rest`` out from it: a rod (a box along x, the cloth 5 cm longer at each
    end), a capsule along x (over both caps, to their tips) or a sphere (pole to pole).
    ``cols`` particles round the axis (the rod's edges half-way between two), ``rows``
    along it. Its flat triangles cut into the collider between the particles (by 2 to 7
    mm: the rod's edges, the capsule's and sphere's curves), and no ray from outside
    reaches the collider without crossing the smooth surface at ``rest`` that the
    particles lie on."""
    centre, shape, _ = WRAPPED[kind]
    v = (np.arange(cols) + 0.5) * 2 * np.pi / cols
    if kind == "box":
        d = np.stack([np.sin(v), np.cos(v)], 1)             # (y, z) directions
        lo, hi = np.zeros(cols), np.full(cols, 0.1)
        for _ in range(60):                                  # bisection: distance = rest
            t = 0.5 * (lo + hi)
            q = np.abs(t[:, None] * d) - 0.02
            inside = (np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)
                      < rest)
            lo, hi = np.where(inside, t, lo), np.where(inside, hi, t)
        along = np.linspace(-0.3, 0.3, rows)[:, None]
        ring_y, ring_z = lo * d[:, 0], lo * d[:, 1]
    else:
        r = shape["radius"] + rest
        if kind == "capsule":        # arc length along the axis, over the caps
            h = shape["half_height"]
            u = np.linspace(-h - 0.5 * np.pi * r, h + 0.5 * np.pi * r, rows)
            alpha = np.clip((np.abs(u) - h) / r, 0.0, None)
            along = (np.sign(u) * (np.minimum(np.abs(u), h) + r * np.sin(alpha)))[:, None]
            ring = (r * np.cos(alpha))[:, None]
        else:
            psi = np.linspace(0.0, np.pi, rows)[:, None]
            along, ring = r * np.cos(psi), r * np.sin(psi)
        ring_y, ring_z = ring * np.cos(v), ring * np.sin(v)
    grid = np.zeros((rows, cols, 3))
    axis, across = (1, 0) if kind == "sphere" else (0, 1)
    grid[..., axis] = along + (centre[1] if kind == "sphere" else 0.0)
    grid[..., across] = ring_y + (0.0 if kind == "sphere" else centre[1])
    grid[..., 2] = ring_z
    # one vertex a pole, the ring closed: quads (i, j), (i + 1, j + 1) as two triangles
    ids = np.arange(rows * cols).reshape(rows, cols)
    poles = [i for i in (0, rows - 1) if kind != "box"]
    ids[poles] = ids[poles, :1]
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols), indexing="ij")
    a, b = ids[i, j], ids[i, (j + 1) % cols]
    c, d = ids[i + 1, j], ids[i + 1, (j + 1) % cols]
    faces = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3),
                            np.stack([b, c, d], -1).reshape(-1, 3)])
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
                  & (faces[:, 2] != faces[:, 0])]
    used, faces = np.unique(faces, return_inverse=True)
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_mesh_cloth(grid.reshape(-1, 3)[used], faces.reshape(-1, 3).tolist(),
                         structural=None, flexion=None, pinned=[])
    getattr(scene, "add_" + kind)(centre, **shape, thickness=thickness)
    return scene


@pytest.mark.slow_cases("capsule", "box")
@pytest.mark.parametrize("kind", ["box", "capsule", "sphere"])
def test_no_collider_shows_through_cloth_resting_on_it(f32, kind):
    """A coarse cloth wrapped all round a rod, a capsule or a sphere, its particles at the
    collider's thickness (and, robustness, at a quarter of it): nothing of the collider
    is visible from outside the cloth, although its flat triangles cut into it by up to
    7 mm (a rod's edges, a capsule's caps)."""
    thickness = 0.005
    sim = tcloth.Simulator(wrapped_cloth(kind, thickness))
    r = tcloth.Renderer(sim, 160, 120, camera=WRAPPED[kind][2], supersample=1, ground=False)
    for rest in (thickness, 0.25 * thickness):
        sim.set_state(positions=wrapped_cloth(kind, rest).positions)
        r.render()
        ids = r.ids()
        assert (ids < r.tri_count).mean() > 0.15
        assert not ((ids >= COLLIDER_ID) & (ids < COLLIDER_ID + 1000)).any(), \
            (rest, ((ids >= COLLIDER_ID) & (ids < COLLIDER_ID + 1000)).sum())


def test_colliders_are_drawn_where_they_are(f32):
    """A coarse cloth (edges of 20 and 28 cm) 2.5 cm behind a thin plate, out of contact
    reach: seen head-on, the plate hides it. Drawing colliders farther than they are by
    half the cloth's longest edge (14 cm) put the cloth in front of it."""
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_cloth(resolution=(3, 3), size=(0.4, 0.4), center=(0, 0, -0.03), plane="xy",
                    structural=None, shear=None, flexion=None, pinned=[])
    scene.add_box((0, 0, 0), (0.1, 0.1, 0.005), thickness=0.005)
    sim = tcloth.Simulator(scene)
    r = tcloth.Renderer(sim, 120, 120, camera={"eye": (0, 0, 1.2), "target": (0, 0, 0),
                                               "fov": 30}, supersample=1, ground=False)
    r.render()
    ids = r.ids()
    col, row = project(r.camera, np.array([[-0.09, -0.09, 0.005], [0.09, 0.09, 0.005]]),
                       120, 120)
    plate = ids[int(min(row)):int(max(row)), int(min(col)):int(max(col))]
    assert plate.size and (plate == COLLIDER_ID).all()
    assert (ids < r.tri_count).any()                       # the cloth round it


def test_shadow_edges_ramp_smoothly(f32):
    """The shadow lookup weighs the 2 x 2 shadow-map texels bilinearly by the point's
    position between their centres: along a line across a cloth's straight shadow edge
    the light ramps through many values, where a plain 2 x 2 average had five steps."""
    import taichi as ti
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_cloth(resolution=(3, 3), size=(1, 1), center=(0, 1, 0), structural=None,
                    shear=None, flexion=None, pinned=[])
    sim = tcloth.Simulator(scene)
    r = tcloth.Renderer(sim, 64, 48, supersample=1, ground=0.0)
    r.render()
    light = np.array(LIGHT_DIR) / np.linalg.norm(LIGHT_DIR)
    # the cloth's edge x = 0.5 at y = 1 casts its shadow on y = 0 at x = 0.5 - light_x / light_y
    edge = 0.5 - light[0] / light[1]
    samples = 400

    @ti.kernel
    def lit_line(r: ti.template(), x0: float, x1: float, out: ti.types.ndarray()):
        for i in range(samples):
            p = ti.Vector([x0 + (x1 - x0) * i / (samples - 1), 0.0, 0.0])
            out[i] = r._unshadowed(p, r._bias(light[1]))
    out = np.zeros(samples, dtype=np.float32)
    lit_line(r, edge - 0.05, edge + 0.05, out)
    assert out[0] < 0.01 and out[-1] > 0.99
    assert np.all(np.diff(out) >= -1e-6)                  # a ramp from shadow to light
    assert len(np.unique(np.round(out, 4))) > 10          # 2 x 2 nearest texels: 5 levels
