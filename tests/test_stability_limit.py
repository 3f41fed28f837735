"""tcloth.scene.stability: omega_max against closed forms, and the power iteration against the
dense eigenvalues."""
import numpy as np
import pytest

import tcloth
from tcloth.scene import stability


def test_two_masses_one_spring():
    """omega^2 = k (1/m1 + 1/m2) for two free particles; k/m1 with the second pinned."""
    k, m1, m2 = 250.0, 0.3, 0.7
    s = tcloth.Scene(gravity=(0, 0, 0))
    s.add_particles([[0, 0, 0], [0.4, 0, 0]], mass=[m1, m2])
    s.add_springs([[0, 1]], k)
    assert stability.omega_max(s) == pytest.approx(np.sqrt(k * (1 / m1 + 1 / m2)), rel=1e-12)
    s = tcloth.Scene(gravity=(0, 0, 0))
    s.add_particles([[0, 0, 0], [0.4, 0, 0]], mass=[m1, m2], pinned=[False, True])
    s.add_springs([[0, 1]], k)
    assert stability.explicit_dt_limit(s) == pytest.approx(2 / np.sqrt(k / m1), rel=1e-12)


def test_chain_closed_form():
    """A chain of n equal masses between two pinned ends, springs k at rest along x:
    omega_max = 2 sqrt(k/m) sin(n pi / (2 (n + 1)))."""
    n, k, m = 9, 40.0, 0.05
    s = tcloth.Scene(gravity=(0, 0, 0))
    x = np.zeros((n + 2, 3))
    x[:, 0] = np.linspace(0, 1, n + 2)
    s.add_particles(x, mass=m, pinned=[True] + [False] * n + [True])
    s.add_springs([[i, i + 1] for i in range(n + 1)], k)
    expected = 2 * np.sqrt(k / m) * np.sin(n * np.pi / (2 * (n + 1)))
    assert stability.omega_max(s) == pytest.approx(expected, rel=1e-10)


def test_power_iteration_matches_dense(monkeypatch):
    s = tcloth.Scene()
    s.add_cloth(resolution=(10, 10), size=(0.5, 0.5), mass=0.2, structural=(1e3, 0.0),
                shear=(2e2, 0.0), flexion=(50.0, 0.0))
    dense = stability.omega_max(s)
    monkeypatch.setattr(stability, "DENSE_BELOW", 0)
    power = stability.omega_max(s, iterations=2000)
    assert power <= dense * (1 + 1e-9)
    assert power == pytest.approx(dense, rel=2e-3)
