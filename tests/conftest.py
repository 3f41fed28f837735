import os

import numpy as np
import pytest

import tcloth
from tcloth.script import load_script

SCENES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes")


@pytest.fixture(scope="module")
def f64():
    """Taichi on the CPU in float64, for accuracy tests."""
    tcloth.init(arch="cpu", precision="f64")
    yield


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
