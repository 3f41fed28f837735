"""tcloth sweep: spec validation, the same table serially and on a Dask LocalCluster, a
worker killed mid-sweep, an interrupted sweep resumed. Sweeps run through the command line
in subprocesses (each with its own Taichi runtime, as the sweep's workers have)."""
import csv
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from tcloth.app.sweep import SpecError, load_spec

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "tests", "data", "sweep_scene.py")


def sweep(spec_text, tmp_path, out, *options):
    """Write the spec, run ``tcloth sweep`` on it; (return code, output, rows)."""
    spec = tmp_path / "spec.toml"
    spec.write_text(f'scene = "{SCENE}"\n' + spec_text)
    # SIGINT as a terminal leaves it: a process started with SIGINT ignored (as this test
    # worker may be, after other tests) keeps ignoring it, and Python then installs no
    # KeyboardInterrupt handler, so the interrupted sweep would run to the end
    proc = subprocess.run([sys.executable, "-m", "tcloth", "sweep", str(spec), "--out",
                           str(out), "--quiet", *options], capture_output=True, text=True,
                          timeout=600,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    path = out / "results.csv"
    rows = list(csv.DictReader(open(path))) if path.exists() else []
    return proc.returncode, proc.stdout + proc.stderr, rows


def test_example_spec_expands_as_written():
    """The issue's example: 2 integrators x 3 dt x 2 stiffnesses = 12 cases; dt = 4e-3
    does not divide 0.25 s, so those cases end at the nearest whole step."""
    spec = load_spec(os.path.join(ROOT, "docs", "sweeps", "hanging_cloth.toml"))
    cases = spec.cases()
    assert len(cases) == 12 and len({c["id"] for c in cases}) == 12
    assert {(c["settings"]["integrator"], c["settings"]["dt"], tuple(c["build"]["structural"]))
            for c in cases} == {(i, dt, (k, 0.05)) for i in ("symplectic_euler", "backward_euler")
                                for dt in (1e-4, 1e-3, 4e-3) for k in (400.0, 4000.0)}
    assert all(c["build"]["resolution"] == [12, 12] for c in cases)
    ends = {c["settings"]["dt"]: (c["steps"], c["t_end"]) for c in cases}
    assert ends[1e-4] == (2500, pytest.approx(0.25)) and ends[4e-3] == (62, pytest.approx(0.248))
    assert spec.reference == {"integrator": "rk4", "dt": 1e-5, "precision": "f64",
                              "options": {}}
    assert len({c["reference_id"] for c in cases}) == 2        # one per stiffness


BAD_SPECS = [
    ({"duration": 1.0, "colour": 1}, "unknown key 'colour'"),
    ({"duration": -0.5}, "duration must be a positive finite number (got -0.5)"),
    ({"duration": 1.0, "vary": {"integrator": ["rk5"]}},
     "vary.integrator[0]: unknown integrator 'rk5'"),
    ({"duration": 1.0, "vary": {"dt": [1e-3, -1e-3]}},
     "vary.dt[1] must be a positive finite number (got -0.001)"),
    ({"duration": 1.0, "vary": {"dt": 1e-3}}, "vary.dt must be a non-empty list of values"),
    ({"duration": 1.0, "vary": {"stiffness": [1.0]}},
     "vary.stiffness: the scene's build() takes no parameter 'stiffness'"),
    ({"duration": 1.0, "build": {"mass": 1.0}},
     "build.mass: the scene's build() takes no parameter 'mass'"),
    ({"duration": 1.0, "vary": {"pair": [{"integrator": "verlet", "dt": 0.0}]}},
     "vary.pair[0].dt must be a positive finite number (got 0.0)"),
    ({"duration": 1.0, "reference": {"integrator": "rk4"}}, "reference needs dt"),
    ({"duration": 1.0, "reference": {"dt": 1e-5, "steps": 3}},
     "unknown key 'steps' in reference"),
    ({"duration": 1.0, "precision": "f16"}, "precision must be 'f32' or 'f64' (got 'f16')"),
    ({"duration": 1.0, "max_steps": 0}, "max_steps must be an integer >= 1 (got 0)"),
    ({"duration": 1.0, "build": "k=3"}, "build must be a table of build parameters (got 'k=3')"),
    ({"duration": 1.0, "arch": "tpu"}, "arch must be one of"),
]


@pytest.mark.parametrize("data, message", BAD_SPECS)
def test_bad_spec_names_key_and_value(data, message):
    with pytest.raises(SpecError) as e:
        load_spec({"scene": SCENE, **data})
    assert message in str(e.value)


def test_missing_scene_and_spec_are_one_line_errors(tmp_path):
    with pytest.raises(SpecError, match="no such scene script"):
        load_spec({"scene": "scenes/nothere.py", "duration": 1.0})
    spec = tmp_path / "s.toml"
    spec.write_text('scene = "scenes/nothere.py"\nduration = 1.0\n')
    proc = subprocess.run([sys.executable, "-m", "tcloth", "sweep", str(spec), "--out",
                           str(tmp_path / "o")], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"tcloth: error: scene 'scenes/nothere.py': no such scene script (looked in "
        f"{os.getcwd()!r} and {str(tmp_path)!r})"]
    assert not (tmp_path / "o").exists()


SMALL = """duration = 0.05
energy_limit = 0.05
[vary]
integrator = ["symplectic_euler", "forward_euler"]
dt = [2e-3, 5e-3]
k = [400.0]
[reference]
integrator = "rk4"
dt = 2.5e-4
"""


@pytest.mark.slow
def test_pool_gives_the_serial_table(tmp_path):
    """Two worker processes on a Dask LocalCluster against one process: the same verdicts,
    first bad steps and errors (to float32 rounding); a case that is unstable is unstable
    in both (and the table holds at least one of each). Forward Euler's growth stays finite
    within 0.05 s at some settings: ``energy_limit`` calls it unstable."""
    rc1, out1, serial = sweep(SMALL, tmp_path, tmp_path / "serial", "--workers", "1")
    rc2, out2, pool = sweep(SMALL, tmp_path, tmp_path / "pool", "--workers", "2")
    assert rc1 == 0 and rc2 == 0, out1 + out2
    assert len(serial) == len(pool) == 4
    assert {r["stable"] for r in serial} == {"True", "False"}
    for a, b in zip(serial, pool):
        assert (a["id"], a["stable"], a["first_bad_step"]) == (b["id"], b["stable"],
                                                               b["first_bad_step"])
        assert a["status"] == b["status"]
        if a["stable"] == "True":
            assert float(a["error"]) == pytest.approx(float(b["error"]), rel=1e-4, abs=1e-7)
            assert 0 < float(a["error"]) < 0.01
    assert (tmp_path / "pool" / "stability_map.png").exists()
    assert (tmp_path / "pool" / "work_precision.png").exists()


def _finished(out):
    folder = out / "cases"
    return {p.name: p.stat().st_mtime_ns for p in folder.iterdir()} if folder.exists() else {}


@pytest.mark.slow
def test_killed_worker_loses_nothing_and_rerun_completes(tmp_path):
    """A case whose build ends its worker process (os._exit) is recorded as such, the
    other cases finish and stay on disk untouched; the rerun runs only what is missing."""
    marker = tmp_path / "crashed"
    spec = (f'duration = 0.02\n[build]\nmarker = "{marker}"\n[vary]\ncrash = [false, true]\n'
            f'dt = [2e-3, 1e-3]\n')
    rc, out, rows = sweep(spec, tmp_path, tmp_path / "o", "--workers", "2")
    assert rc == 4, out
    assert marker.exists()
    status = {(r["crash"], r["dt"]): r["status"] for r in rows}
    assert status[("False", "0.002")] == status[("False", "0.001")] == "ok"
    assert status[("True", "0.002")] == "worker died while running it"
    assert status[("True", "0.001")].startswith("not run")
    before = _finished(tmp_path / "o")
    assert len(before) == 2
    rc, out, rows = sweep(spec, tmp_path, tmp_path / "o", "--workers", "2")
    assert rc == 0, out
    assert "4 cases (2 run now, 2 from earlier runs)" in out
    after = _finished(tmp_path / "o")
    assert len(after) == 4 and all(after[name] == t for name, t in before.items())
    assert all(r["status"] == "ok" for r in rows)


@pytest.mark.slow
def test_interrupted_sweep_resumes_computing_each_case_once(tmp_path):
    """SIGINT in the middle of a serial sweep: exit 4 with the resume hint, the finished
    cases kept; the rerun computes only the others, and rerunning again computes none."""
    marker = tmp_path / "interrupted"
    spec = (f'duration = 0.02\n[build]\nmarker = "{marker}"\n[vary]\n'
            f'interrupt = [false, true]\ndt = [2e-3, 1e-3]\n')
    rc, out, rows = sweep(spec, tmp_path, tmp_path / "o", "--workers", "1")
    assert rc == 4 and "interrupted" in out and "run the same command again" in out, out
    before = _finished(tmp_path / "o")
    assert len(before) == 2
    rc, out, rows = sweep(spec, tmp_path, tmp_path / "o", "--workers", "1")
    assert rc == 0 and "4 cases (2 run now, 2 from earlier runs)" in out, out
    after = _finished(tmp_path / "o")
    assert all(after[name] == t for name, t in before.items())
    rc, out, again = sweep(spec, tmp_path, tmp_path / "o", "--workers", "1")
    assert rc == 0 and "4 cases (0 run now, 4 from earlier runs)" in out
    assert _finished(tmp_path / "o") == after
    for a, b in zip(rows, again):
        assert np.isclose(float(a["error"] or "nan"), float(b["error"] or "nan"),
                          equal_nan=True) and a["stable"] == b["stable"]


@pytest.mark.slow
def test_ctrl_c_on_a_pool_sweep_prints_its_line_and_exits_4(tmp_path):
    """Ctrl-C in a terminal signals the whole process group: the Dask pool's processes
    ignore it (dying of it, they would make the sweep print Dask's tracebacks or wait for
    Client.__del__), so only the line and exit code 4 remain."""
    import glob
    import time
    spec = tmp_path / "spec.toml"
    spec.write_text(f'scene = "{SCENE}"\nduration = 0.5\n'
                    '[vary]\nk = [100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0]\n'
                    'dt = [1e-4]\n')
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "tcloth", "sweep", str(spec), "--out",
                             str(out), "--quiet", "--workers", "2"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 300
    while not glob.glob(str(out / "cases" / "*.json")) and time.time() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGINT)
    interrupted = time.time()
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 4, stdout + stderr
    assert "interrupted" in stderr and "run the same command again" in stderr
    assert "Traceback" not in stderr and "Error" not in stderr, stderr
    assert time.time() - interrupted < 30


def test_plots_keep_markers_and_labels_readable(tmp_path, monkeypatch):
    """The sweep example's plots as a reader sees them: the stability map's legend below
    the panels (inside, it hid a marker), ticks at the swept values on a short log range
    (matplotlib labelled minor ticks there, '3x10^3 4x10^3' running together), markers
    off the axes' edges, and a series with one stable point saying so, not 'order nan'."""
    import json
    import matplotlib.figure
    from tcloth.app.sweep import plots
    spec = load_spec(os.path.join(ROOT, "docs", "sweeps", "hanging_cloth.toml"))
    rows = []
    for c in spec.cases():
        row = {k: (json.dumps(v) if isinstance(v, list) else v) for k, v in c["values"].items()}
        unstable = c["values"]["integrator"] == "symplectic_euler" and c["values"]["dt"] > 1e-3
        stiff = c["values"]["structural"][0] > 1000
        row.update(id=c["id"], stable=not unstable and not (stiff and c["values"]["dt"] > 1e-4
                   and c["values"]["integrator"] == "symplectic_euler"),
                   error=1e-3 * c["values"]["dt"] / 1e-3, ms_per_step=0.1, steps=c["steps"])
        rows.append(row)
    figures = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda self, *a, **k: figures.append(self))
    plots.plot_all(spec, rows, str(tmp_path))
    stability, precision = figures
    panels = [ax for ax in stability.axes if ax.get_visible()]
    assert stability.legends and all(ax.get_legend() is None for ax in panels)
    for ax in panels:
        assert [t.get_text() for t in ax.get_xticklabels()] == ["400", "4000"]
        assert all(t.get_text() == "" for t in ax.xaxis.get_ticklabels(minor=True))
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        assert x0 < 400 and x1 > 4000 and y0 < 1e-4 and y1 > 4e-3
    labels = [t.get_text() for legend in precision.legends for t in legend.get_texts()]
    assert not any("nan" in label for label in labels)
    assert any("one stable point" in label for label in labels), labels


def test_a_case_studies_its_own_dt():
    """A sweep's case is not split where a step fails (a split step is a smaller dt, and
    the case's verdict is about its own), unless its options ask for it."""
    from tcloth.app.sweep import worker
    for options, pieces in (({}, 1), ({"split": 8}, 8)):
        settings = {"integrator": "symplectic_euler", "dt": 1e-3, "precision": "f32",
                    "options": options}
        sim = worker._simulator(SCENE, "cpu", {}, settings, ("split", pieces))
        assert sim.settings["split"] == pieces
