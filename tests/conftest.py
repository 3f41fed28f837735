import os

import numpy as np
import pytest
import taichi as ti

import tcloth
from tcloth.app.script import load_script

SCENES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes")

# Taichi keeps compiled kernels on disk (its offline cache) and, past 100 MB, drops the
# least recently used quarter. The suite compiles far more than that, so by default the
# cache thrashes: a scene that a later module, a scene script run by the command line or
# the long set compiles again finds its kernels gone (hanging_cloth's first step: 22 s
# compiling, 8 s from the cache). The tests, and the processes they start, keep 2 GB
# (the most Taichi's setting holds: a C int).
os.environ.setdefault("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES", str(2_000_000_000))
# A simulator compiles its contact kernels as they are first needed, not all of them
# while it is built (Simulator(compile_ahead=...)): a test takes a few steps of a scene
# of its own and would compile many it never runs; the numbers are the same
# (tests/test_compile_once.py, which checks both). Inherited by the command-line runs
# the tests start.
os.environ.setdefault("TCLOTH_COMPILE_AHEAD", "0")
# Taichi compiles the tests' kernels with its control-flow-graph optimisation off
# (tcloth.init(quick_compile=...)): the same numbers bit for bit
# (tests/test_compile_once.py), about half the compile time of a scene with contact, and
# the suite's time is mostly compiling. The quick set's scene renders run the command line
# as it ships.
os.environ.setdefault("TCLOTH_QUICK_COMPILE", "1")


def pytest_collection_modifyitems(config, items):
    """``slow`` marks the long stress, convergence and every-scene tests (the README's test
    command leaves them out: ``-m "not slow"``; ``.ci/run`` runs them after it). A
    parametrised test marks its long cases at its definition with
    ``@pytest.mark.slow_cases(id, ...)`` (pytest's ids); an id that names none of its
    cases is an error, since a renamed parameter would put a long case into the quick set
    without a word."""
    named, seen = {}, set()
    for item in items:
        mark = item.get_closest_marker("slow_cases")
        if mark is None:
            continue
        key = item.nodeid.partition("[")[0]
        named[key] = set(mark.args)
        case = item.callspec.id
        if case in mark.args:
            item.add_marker(pytest.mark.slow)
            seen.add((key, case))
    chosen = any("::" in arg for arg in config.args)       # named tests collect alone
    stale = sorted(f"{key}[{case}]" for key, cases in named.items() for case in cases
                   if (key, case) not in seen)
    if stale and not chosen:
        raise pytest.UsageError(f"slow_cases names cases that do not exist: {stale}")


# (generation, module) of the last runtime use_runtime made
_made = None
# Taichi's CPU runtime crashes (a segmentation fault) when a program holds 512 field
# trees; a simulator makes 14 to 20. A module's program is made again past this many.
TREES = 384


def _trees():
    """The field trees of the current Taichi program (0 where it has none)."""
    prog = ti.lang.impl.get_runtime().prog
    return prog.get_snode_tree_size() if prog is not None else 0


def use_runtime(precision, module):
    """Taichi on the CPU in PRECISION with the default loop settings for the tests of
    MODULE (a module name): initialised again where this worker runs otherwise now, where
    a test called tcloth.init itself, or where the runtime was made for another module.
    A module's tests share their compiled kernels and the simulators their fixtures keep;
    a new module starts a new program (a long-lived one would gather every earlier
    module's fields: Taichi's CPU runtime holds a bounded number of field trees), and so
    does a module whose program holds more than TREES (the contact module's slow set on
    one worker crashed there)."""
    global _made
    rt = tcloth.runtime
    if (_made != (rt.generation(), module) or rt.precision() != precision
            or not rt.cpu() or rt.serial_below() != rt.SERIAL_BELOW or _trees() > TREES):
        tcloth.init(arch="cpu", precision=precision, serial_below=rt.SERIAL_BELOW)
        _made = (rt.generation(), module)


@pytest.fixture
def f64(request):
    """float64, for accuracy tests."""
    use_runtime("f64", request.module.__name__)


@pytest.fixture
def f32(request):
    """float32, the default, where a changed rounding would show soonest."""
    use_runtime("f32", request.module.__name__)


@pytest.fixture
def fresh_f32():
    """float32 in a new program of its own, for a test that builds a large simulator of
    its own and shares nothing: a module of many such (the mesh colliders' stress set)
    gathered field trees in one program past Taichi's bound, and its worker crashed
    (a segmentation fault in a field's to_numpy)."""
    tcloth.init(arch="cpu", precision="f32", serial_below=tcloth.runtime.SERIAL_BELOW)


def scene_module(name):
    """The scene script scenes/NAME.py as a module."""
    return load_script(os.path.join(SCENES, name + ".py"))[0]


def random_network(n=7, seed=0, k=(50.0, 200.0), kd=0.0, pin=None, gravity=(0.0, 0.0, 0.0),
                   velocity_scale=0.5):
    """A small random spring network: scene, pairs, rest lengths."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 3))
    v = velocity_scale * rng.normal(size=(n, 3))
    scene = tcloth.Scene(gravity=gravity)
    pinned = np.zeros(n, dtype=bool) if pin is None else pin
    scene.add_particles(x, mass=rng.uniform(0.5, 2.0, n), velocities=v, pinned=pinned)
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)
                      if rng.random() < 0.6 or j == i + 1])
    rest = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) * rng.uniform(0.8, 1.2, len(pairs))
    scene.add_springs(pairs, stiffness=rng.uniform(*k, len(pairs)), damping=kd, rest_length=rest)
    return scene


def hanging_chain(n=10, m=0.01, k=50.0, l0=0.05, g=9.81):
    """A chain of n masses hanging from a pinned end, starting at rest length, and its
    closed-form equilibrium: spring i from the top carries the weight of the masses below
    it, (n - i + 1) m g, and stretches by that over k. Returns (scene, the particles'
    heights at equilibrium, the total stretch)."""
    scene = tcloth.Scene(gravity=(0.0, -g, 0.0), air_drag=0.02)
    x = np.zeros((n + 1, 3))
    x[:, 1] = -l0 * np.arange(n + 1)
    scene.add_particles(x, mass=m, pinned=[True] + [False] * n)
    scene.add_springs([[i, i + 1] for i in range(n)], stiffness=k, damping=0.05)
    stretch = (n - np.arange(n)) * m * g / k
    return scene, -np.concatenate([[0.0], np.cumsum(l0 + stretch)]), stretch.sum()


def energy_gradient(sim, x0, term, entries=None, h=1e-6):
    """Central finite differences of sim.energy()[term] at positions x0, (N,3); entries:
    the (particle, coordinate) pairs to difference (default all)."""
    grad = np.full(x0.shape, np.nan)
    if entries is None:
        entries = [(p, c) for p in range(len(x0)) for c in range(3)]
    for p, c in entries:
        e = []
        for s in (1, -1):
            x = x0.copy()
            x[p, c] += s * h
            sim.set_state(positions=x)
            e.append(sim.energy()[term])
        grad[p, c] = (e[0] - e[1]) / (2 * h)
    sim.set_state(positions=x0)
    return grad


def numpy_forces(scene, x, v):
    """Independent reference: gravity, drag and the lecture's spring + axial damping force."""
    sp = scene.springs
    c = scene.air_drag + scene.air_damping * scene.masses      # per particle, N s/m
    f = scene.masses[:, None] * scene.gravity - c[:, None] * v
    for (i, j), ks, kd, l0 in zip(sp["pairs"], sp["stiffness"], sp["damping"], sp["rest_length"]):
        d = x[i] - x[j]
        length = np.linalg.norm(d)
        n = d / length
        fi = -ks * (length - l0) * n - kd * np.dot(v[i] - v[j], n) * n
        f[i] += fi
        f[j] -= fi
    return f


def check_gradients(trajectory, loss, result, names, rng, array_step):
    """Each parameter of ``names``: its gradient (a scalar's, or an array's directional
    derivative along a random direction) against central differences (a scalar's step
    1e-6 of its value, an array's ``array_step``), within 1e-5 relative."""
    for name in names:
        value = trajectory.value(name)
        if np.isscalar(value):
            direction, step = 1.0, 1e-6 * abs(value) if value else 1e-6
            adjoint = result.grad[name]
        else:
            direction, step = rng.standard_normal(value.shape), array_step
            adjoint = float((result.grad[name] * direction).sum())
        fd = trajectory.central_difference(loss, name, direction, step)
        assert abs(adjoint - fd) <= 1e-5 * abs(fd), (name, adjoint, fd)


def check_step_terms(trajectory, x, v):
    """A ``tcloth.grad.Trajectory``'s adjoint kernel against its simulator from (x, v)
    (set in the simulator): symplectic Euler's force is the simulator's to the last
    digits; backward Euler's (and projective's) residual vanishes at the simulator's
    step. Returns None, or (x1, h, the inertia term M (x1 - x - h v) / h^2) of the step."""
    sim, adj = trajectory.sim, trajectory.adjoint
    if not trajectory.implicit:
        adj.set_inputs(x, v)
        f = adj.evaluate(sim.dt, 0.0)
        np.testing.assert_allclose(f, sim.forces(), rtol=0, atol=1e-12 * np.abs(f).max())
        return None
    sim.step(1)
    x1, h, free = sim.positions(), sim.dt, trajectory.free
    adj.set_inputs(x, v, x1)
    g = adj.evaluate(h, h)
    inertia = adj.mass.to_numpy()[:, None] * (x1 - x - h * v) / h ** 2
    assert np.abs(g[free]).max() < 1e-9 * np.abs(inertia[free]).max()
    return x1, h, inertia
