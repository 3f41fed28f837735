"""Flexible GMRES (tcloth.grad.krylov) against NumPy's dense solve: a non-symmetric
system, a preconditioner that changes from one application to the next, restarts and the
iteration cap."""
import numpy as np

from tcloth.grad.krylov import fgmres


def _system(n=120, seed=0):
    rng = np.random.default_rng(seed)
    a = np.eye(n) * 4.0 + rng.standard_normal((n, n)) / np.sqrt(n)
    a[np.arange(n - 1), np.arange(1, n)] += 1.5          # far from symmetric
    return a, rng.standard_normal(n), rng


def test_fgmres_solves_a_nonsymmetric_system_with_a_changing_preconditioner():
    a, b, rng = _system()
    diagonal = np.diag(a)

    def precondition(z):            # Jacobi, disturbed afresh at each application
        return z / diagonal * (1.0 + 0.3 * rng.random(z.size))

    for restart in (None, 7):
        x, iterations, residual = fgmres(lambda z: a @ z, precondition, b, 1e-11,
                                         restart=restart, max_iterations=1000)
        assert residual <= 1e-11
        assert np.isclose(residual, np.linalg.norm(b - a @ x) / np.linalg.norm(b))
        assert np.allclose(x, np.linalg.solve(a, b), rtol=0.0, atol=1e-9)
        assert 0 < iterations < 1000


def test_fgmres_stops_at_its_cap_and_reports_the_true_residual():
    a, b, _ = _system(seed=1)
    x, iterations, residual = fgmres(lambda z: a @ z, lambda z: z, b, 1e-14,
                                     max_iterations=5)
    assert iterations == 5
    assert np.isclose(residual, np.linalg.norm(b - a @ x) / np.linalg.norm(b))
    assert 1e-14 < residual < 1.0
    x, iterations, residual = fgmres(lambda z: a @ z, lambda z: z, np.zeros_like(b), 1e-8)
    assert iterations == 0 and residual == 0.0 and not x.any()
