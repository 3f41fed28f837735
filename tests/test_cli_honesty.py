"""The command line means what it says: --dt sets the step and
the steps a frame follow it, bad timing values are refused in one line naming the option,
`tcloth list` shows whole sentences; and the smaller promises: add_cloth's default pins
with a fabric, contact_stats() after reset(), Fabric's checks, a scene's bad build
parameter named, a fabric on a closed mesh."""
import os
import subprocess
import sys

import numpy as np
import pytest

import tcloth
from tcloth.app import cli
from tcloth.contact.stage import STATS
from tcloth.app.script import build_scene, describe, load_script

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
G = 9.81

# a free cloth of soft springs at rest length: its centre of mass falls freely
FALLING = ('"""A free cloth falls. It has no pins."""\n'
           "import tcloth\n"
           'CONFIG = {"integrator": "symplectic_euler", "dt": 2.5e-4, "steps_per_frame": 133,\n'
           '          "frames": 120}\n'
           "def build(resolution=(3, 3)):\n"
           "    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))\n"
           "    scene.add_cloth(resolution=resolution, size=(0.2, 0.2), center=(0.0, 1.0, 0.0),\n"
           "                    structural=(10.0, 0.0), shear=None, flexion=None, pinned=[])\n"
           "    return scene\n")


@pytest.fixture
def falling(tmp_path):
    path = tmp_path / "falling.py"
    path.write_text(FALLING)
    return str(path)


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "tcloth", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def mean_height(obj):
    with open(obj) as f:
        return np.mean([float(line.split()[2]) for line in f if line.startswith("v ")])


def free_fall_drop(steps, dt):
    """Symplectic Euler from rest under gravity: v_k = -g k dt, so after n steps the
    drop is g dt^2 (1 + 2 + ... + n)."""
    return G * dt * dt * steps * (steps + 1) / 2


# -- 3: --dt ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_dt_alone_fills_a_frame_with_its_steps(falling, tmp_path):
    """The script says 133 steps of 0.25 ms a frame; --dt 0.01 alone runs
    round(1 / (30 * 0.01)) = 3 steps a frame, so that a frame is 1/30 s of simulated time
    again (133 of them would be 1.33 s): the centre of mass's drop over one frame is
    symplectic Euler's free fall over 3 steps, and the line the CLI prints says so."""
    meshes = tmp_path / "meshes"
    res = run_cli("render", falling, "--dt", "0.01", "--frames", "2", "--out",
                  str(tmp_path / "frames"), "--width", "16", "--height", "12",
                  "--supersample", "1", "--quiet", "--meshes", str(meshes))
    assert res.returncode == 0, res.stderr
    drop = mean_height(meshes / "frame_00000.obj") - mean_height(meshes / "frame_00001.obj")
    assert drop == pytest.approx(free_fall_drop(3, 0.01), rel=1e-3)
    assert "2 frames of 3 steps of dt = 0.01 s: 0.03 s simulated" in res.stderr


def test_view_substeps_follow_dt_unless_given(falling, monkeypatch, capsys):
    """`tcloth view --dt` gives the window round(1 / (fps dt)) substeps a frame, unless
    --substeps says otherwise; without --dt the script's own (a stand-in window records
    what it was given: no display is needed)."""
    import tcloth.viewer as viewer
    given = []

    class Window:
        def __init__(self, sim, substeps, **options):
            given.append((substeps, sim.dt))
            self.controls = viewer.Controls(sim, substeps)

        def run(self, frames=None, screenshot=None):
            return 0

    monkeypatch.setattr(viewer, "check_display", lambda: None)
    monkeypatch.setattr(viewer, "Viewer", Window)
    monkeypatch.setattr(viewer.Controls, "stats",
                        lambda self: {"fps": 0.0, "ms_per_substep": 0.0})
    for args in (["--dt", "0.01"], ["--dt", "0.004"], ["--dt", "0.01", "--substeps", "1"],
                 []):
        assert cli.main(["view", falling, *args]) == 0, capsys.readouterr().err
    assert given == [(3, 0.01), (8, 0.004), (1, 0.01), (133, 2.5e-4)]
    assert "3 substeps of dt = 0.01 s a frame" in capsys.readouterr().err


BAD = [("render", "--dt", "0"), ("render", "--dt", "-1"), ("render", "--dt", "nan"),
       ("render", "--dt", "inf"), ("render", "--steps-per-frame", "0"),
       ("render", "--frames", "0"), ("view", "--substeps", "0"), ("view", "--dt", "-0.5"),
       ("view", "--frames", "-3")]


@pytest.mark.parametrize("command, option, value", BAD, ids=[" ".join(b) for b in BAD])
def test_bad_timing_values_are_refused_in_one_line(falling, tmp_path, capsys, command,
                                                   option, value):
    code = cli.main([command, falling, option, value, *(["--out", str(tmp_path / "f")]
                                                        if command == "render" else [])])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith(f"tcloth: error: {option} "), err
    assert float(err[0].split()[3].rstrip(":")) == pytest.approx(float(value), nan_ok=True)


def test_bad_config_values_are_named_by_their_key(tmp_path):
    """The same checks on a script's CONFIG, through the real process: exit code 2 and one
    line naming the key (fps has no option), no traceback."""
    script = tmp_path / "slow.py"
    script.write_text(FALLING.replace('"frames": 120', '"frames": 120, "fps": 0'))
    res = run_cli("view", str(script))
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [
        f"tcloth: error: scene script {str(script)!r}: CONFIG['fps'] = 0: must be frames "
        "per second, finite and > 0"]


# -- 6: the smaller ones ----------------------------------------------------------------------
def test_list_shows_each_first_sentence_whole(tmp_path, capsys):
    (tmp_path / "wrapped.py").write_text(
        '"""A first sentence that wraps\nover two lines (``see.py``), e.g. this. A second.\n'
        '\nMore."""\n')
    (tmp_path / "bare.py").write_text("x = 1\n")
    assert cli.main(["list", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    # neither script builds a scene: its integrator, dt, steps and particles are unknown
    assert lines == ["script      integrator  dt  steps a frame  particles",
                     "bare.py     ?           ?   ?              ?          (no description)",
                     "wrapped.py  ?           ?   ?              ?          A first sentence "
                     "that wraps over two lines (see.py), e.g. this."]
    drape = describe(os.path.join(ROOT, "scenes", "drape.py"))
    assert drape.startswith("Cusick's drape test") and drape.endswith("hangs into folds.")
    for name in os.listdir(os.path.join(ROOT, "scenes")):
        if name.endswith(".py"):
            assert describe(os.path.join(ROOT, "scenes", name))[-1] in ".!?", name


def test_add_cloth_pins_two_corners_by_default_even_with_a_fabric():
    """The API's default pinned=[(0, 0), (nx - 1, 0)] holds with fabric= too; pinned=[]
    pins none (as the README's fabric fragment says)."""
    scene = tcloth.Scene()
    cloth = scene.add_cloth(resolution=(4, 3), size=(0.3, 0.2), fabric="denim")
    assert sorted(np.flatnonzero(scene.pinned)) == sorted([cloth.particles[0, 0],
                                                          cloth.particles[0, 3]])
    scene.add_cloth(resolution=(4, 3), size=(0.3, 0.2), fabric="denim", pinned=[])
    assert scene.pinned.sum() == 2
    with open(os.path.join(ROOT, "README.md")) as f:
        readme = f.read()
    fragment = readme[readme.index("tcloth.Fabric(density"):readme.index("scene.set_bending")]
    assert "pinned=[]" in fragment and "(0, 0), (nx-1, 0) pinned" in fragment


@pytest.mark.slow
@pytest.mark.parametrize("batch", [True, False])
def test_contact_stats_start_again_at_reset(batch):
    """A cloth falling under 100 m/s^2 onto the ground, 2 ms steps: the collider stops its
    particles' paths (counted inside batches of steps, or by the contact stage after each
    step, timed). After reset() the counts and the time are zero, and the same run counts
    the same again."""
    tcloth.init(arch="cpu")
    scene = tcloth.Scene(gravity=(0.0, -100.0, 0.0))
    scene.add_cloth(resolution=(3, 3), size=(0.1, 0.1), center=(0.0, 0.06, 0.0), pinned=[],
                    flexion=None)
    scene.add_plane()
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=0.002, batch=batch)
    assert (sim.fusion() is None) == batch
    sim.step(40)
    first = sim.contact_stats()
    assert first["collider_paths_cut"] > 0 and (batch or first["seconds"] > 0)
    sim.reset()
    after = sim.contact_stats()
    assert all(after[key] == 0 for key in STATS), after
    sim.step(40)
    again = sim.contact_stats()
    assert {k: v for k, v in again.items() if k != "seconds"} == \
        {k: v for k, v in first.items() if k != "seconds"}
    assert batch or again["seconds"] > 0


@pytest.mark.parametrize("argument, value", [("stretch", "abc"), ("density", "heavy"),
                                             ("shear", None), ("bending", ["a", "b"]),
                                             ("damping", "lots")])
def test_fabric_refuses_non_numbers_naming_them(argument, value):
    numbers = {"density": 0.2, "stretch": 100.0, "shear": 10.0, "bending": 1e-5}
    with pytest.raises(tcloth.SceneError, match=f"^{argument} must be .*got"):
        tcloth.Fabric(**{**numbers, argument: value})


def test_a_bad_build_parameter_is_named(tmp_path):
    """`--set rings=0` on the drape: exit code 2 and a line naming rings and 0 (was an
    IndexError from inside the disc mesh); a script's own exception names the call."""
    res = run_cli("render", os.path.join(ROOT, "scenes", "drape.py"), "--set", "rings=0",
                  "--out", str(tmp_path / "f"))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines()[-1] == "tcloth: error: rings must be >= 1 (got 0)"
    script = tmp_path / "picky.py"
    script.write_text("def build(n=3):\n    return [0, 1, 2][n]\n")
    module, _ = load_script(str(script))
    with pytest.raises(tcloth.app.script.ScriptError, match=r"build\(n=7\) raised IndexError"):
        build_scene(module, str(script), {"n": 7})


def icosahedron(radius):
    """(vertices (12, 3), faces (20, 3)) of a regular icosahedron, wound outward."""
    g = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
                  [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]])
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True), f


def test_a_fabric_on_a_closed_mesh_is_a_membrane_without_bending():
    """A fabric that bends is refused on a closed mesh with a line that says how (bending=0)
    and adds nothing; without_bending() builds it, at rest in its curved shape (no force),
    and blown up uniformly by (1 + e) its membrane pulls back with the virtual work of
    W = A C e^2 (both stretch conditions at strain e, no shear): sum_i f_i . x_i =
    -2 A C e, A the rest area."""
    tcloth.init(arch="cpu", precision="f64")
    x, faces = icosahedron(0.1)
    fabric = tcloth.Fabric(density=0.2, stretch=500.0, shear=20.0, bending=1e-5)
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    with pytest.raises(tcloth.SceneError, match=r"flat rest shape.*closed or curved mesh.*"
                                                r"bending=0.*without_bending\(\)"):
        scene.add_mesh_cloth(x, faces.tolist(), fabric=fabric)
    assert scene.num_particles == 0
    scene.add_mesh_cloth(x, faces.tolist(), fabric=fabric.without_bending())
    assert scene.bending is None
    sim = tcloth.Simulator(scene)
    assert np.abs(sim.forces()).max() < 1e-12
    e = 0.01
    sim.set_state(positions=(1 + e) * x)
    a, b, c = (x[faces[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    assert np.sum(sim.forces() * x) == pytest.approx(-2 * area * 500.0 * e, rel=1e-9)
