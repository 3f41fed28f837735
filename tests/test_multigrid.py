"""The projective solver's grid multigrid, against dense NumPy linear algebra: Galerkin
coarse operators, V-cycle convergence to the exact solution, pinned nodes."""
import numpy as np
import pytest
import taichi as ti

from tcloth.model.grid import stencil as grid_stencil
from tcloth.integrators import block_multigrid, galerkin, multigrid

PROVOT = grid_stencil((True, True, True))


def random_grid_matrix(ny, nx, pinned, seed=0):
    """A random spring network on the Provot stencil with masses: the dense matrix
    (built spring by spring, pinned rows and columns 0) and its stencil weights."""
    rng = np.random.default_rng(seed)
    n = ny * nx
    dense = np.diag(rng.uniform(20.0, 80.0, n))
    for j in range(ny):
        for i in range(nx):
            for di, dj in PROVOT[1::2]:            # one end of each spring
                if 0 <= j + dj < ny and 0 <= i + di < nx:
                    a, b, w = j * nx + i, (j + dj) * nx + i + di, rng.uniform(100.0, 1000.0)
                    dense[[a, b], [a, b]] += w
                    dense[a, b] -= w
                    dense[b, a] -= w
    free = np.ones(n, dtype=bool)
    free[[j * nx + i for j, i in pinned]] = False
    dense[~free, :] = 0.0
    dense[:, ~free] = 0.0
    weights = np.zeros((ny, nx, len(PROVOT)))
    for j in range(ny):
        for i in range(nx):
            for k, (di, dj) in enumerate(PROVOT):
                if 0 <= j + dj < ny and 0 <= i + di < nx:
                    weights[j, i, k] = dense[j * nx + i, (j + dj) * nx + i + di]
    return dense, weights, free


def hat_prolongation(n_fine):
    """Bilinear interpolation from coarse nodes at fine positions 2c: hat functions."""
    c = np.arange(n_fine // 2 + 1)
    return np.maximum(0.0, 1.0 - np.abs(np.arange(n_fine)[:, None] - 2 * c[None, :]) / 2.0)


@pytest.mark.parametrize("ny, nx", [(13, 18), (9, 8)])
def test_coarse_operators_are_the_galerkin_products(ny, nx):
    dense, weights, _ = random_grid_matrix(ny, nx, pinned=[(0, 0), (0, nx - 1)])
    py, px = hat_prolongation(ny), hat_prolongation(nx)
    assert np.array_equal(py, galerkin.prolongation_1d(ny))
    p = np.kron(py, px)
    coarse = galerkin.galerkin(weights, PROVOT)
    assert np.allclose(galerkin.dense_matrix(coarse, galerkin.coarse_stencil(PROVOT)), p.T @ dense @ p,
                       rtol=0, atol=1e-10 * np.abs(dense).max())
    assert np.allclose(galerkin.dense_matrix(weights, PROVOT), dense)
    assert len(galerkin.coarse_stencil(PROVOT)) == 21
    assert galerkin.coarse_stencil(galerkin.coarse_stencil(PROVOT)) == galerkin.coarse_stencil(PROVOT)


@pytest.mark.parametrize("ny, nx", [(24, 19), (40, 40)])
def test_vcycles_converge_to_the_dense_solution(f64, ny, nx):
    pinned = [(0, 0), (0, nx - 1), (ny // 2, nx // 2)]
    dense, weights, free = random_grid_matrix(ny, nx, pinned, seed=ny)
    solver = multigrid.GridMultigrid(nx, ny, PROVOT)
    assert solver.levels >= 3
    solver.set_matrix(weights)
    rng = np.random.default_rng(1)
    rhs = rng.normal(size=(ny * nx, 3)) * free[:, None]
    exact = np.zeros_like(rhs)
    exact[free] = np.linalg.solve(dense[np.ix_(free, free)], rhs[free])
    e = np.zeros_like(rhs)
    errors = []
    for _ in range(8):
        residual = rhs - dense @ e
        e += solver.vcycle(residual.reshape(ny, nx, 3)).reshape(-1, 3)
        errors.append(np.abs(e - exact).max() / np.abs(exact).max())
        assert np.all(e[~free] == 0.0)
    rates = np.array(errors[1:]) / errors[:-1]
    assert errors[0] < 0.1 and rates.max() < 0.3, errors
    assert errors[-1] < 1e-5


def test_a_grid_of_at_most_64_nodes_is_solved_exactly(f64):
    """The coarsest level's inverse (Gauss-Jordan in a kernel, pinned rows skipped), on
    scalar weights from NumPy and on blocks assembled in the kernel."""
    rhs = np.random.default_rng(2).normal(size=(56, 3))
    dense, weights, free = random_grid_matrix(8, 7, pinned=[(3, 3)])
    solver = multigrid.GridMultigrid(7, 8, PROVOT)
    assert solver.levels == 1
    solver.set_matrix(weights)
    e = solver.vcycle((rhs * free[:, None]).reshape(8, 7, 3)).reshape(-1, 3)
    assert np.allclose(dense @ e, rhs * free[:, None], atol=1e-12)
    assert np.all(e[~free] == 0.0)
    dense, weights, free = random_block_grid_matrix(8, 7, pinned=[(3, 3), (7, 0)])
    solver = block_multigrid.BlockGridMultigrid(7, 8, PROVOT)
    assert solver.levels == 1
    solver.set_matrix(weights)
    e = solver.vcycle((rhs * free[:, None]).reshape(8, 7, 3)).ravel()
    assert np.allclose(dense @ e, (rhs * free[:, None]).ravel(), atol=1e-12)
    assert np.all(e.reshape(-1, 3)[~free] == 0.0)


def test_two_level_cycle_is_smoothing_coarse_correction_smoothing(f64):
    """On a grid whose coarse level is the coarsest (35 nodes), in dense NumPy:
    e1 = omega D^-1 r, e2 = e1 + P A_c^-1 P^T (r - A e1), B r = e2 + omega D^-1 (r - A e2);
    B is symmetric."""
    ny, nx = 13, 9
    dense, weights, free = random_grid_matrix(ny, nx, pinned=[(0, 0), (12, 4)], seed=3)
    solver = multigrid.GridMultigrid(nx, ny, PROVOT)
    assert solver.shapes == [(13, 9), (7, 5)]
    solver.set_matrix(weights)
    p = np.kron(hat_prolongation(ny), hat_prolongation(nx)) * free[:, None]
    coarse = p.T @ dense @ p
    smoother = solver.omega[0] * np.where(free, 1.0 / np.where(free, np.diag(dense), 1.0), 0.0)

    def cycle(r):
        e = smoother[:, None] * r
        e = e + p @ np.linalg.solve(coarse, p.T @ (r - dense @ e))
        return e + smoother[:, None] * (r - dense @ e)
    rng = np.random.default_rng(4)
    rhs, other = rng.normal(size=(2, ny * nx, 3)) * free[:, None]
    for r in (rhs, other):
        expected = cycle(r)
        got = solver.vcycle(r.reshape(ny, nx, 3)).reshape(-1, 3)
        assert np.allclose(got, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
    assert np.isclose(np.sum(rhs * solver.vcycle(other.reshape(ny, nx, 3)).reshape(-1, 3)),
                      np.sum(other * solver.vcycle(rhs.reshape(ny, nx, 3)).reshape(-1, 3)),
                      rtol=1e-10)


@ti.kernel
def _add_fine_diagonal(mg: ti.template(), extra: ti.types.ndarray()):
    for j, i in ti.ndrange(extra.shape[0], extra.shape[1]):
        mg.set_fine_diagonal(j, i, ti.Vector([extra[j, i, 0], extra[j, i, 1], extra[j, i, 2]]))


def test_a_fine_diagonal_per_component_is_in_the_smoother_and_the_product(f64):
    """``set_fine_diagonal`` with a different addition for x, y and z (projective's
    colliders: n n^T's diagonal): the two-level cycle of the test above, each component
    on its own fine matrix A + diag(extra_c) (its smoother's diagonal too), the coarse
    level built from A alone; pinned nodes keep 0."""
    ny, nx = 13, 9
    dense, weights, free = random_grid_matrix(ny, nx, pinned=[(0, 0), (12, 4)], seed=5)
    solver = multigrid.GridMultigrid(nx, ny, PROVOT, varied=True)
    solver.set_matrix(weights)
    solver.set_fine_base(weights[..., PROVOT.index((0, 0))])
    rng = np.random.default_rng(6)
    extra = rng.uniform(0.0, 5000.0, size=(ny * nx, 3)) * (rng.uniform(size=(ny * nx, 1)) < 0.4)
    _add_fine_diagonal(solver, extra.reshape(ny, nx, 3))
    p = np.kron(hat_prolongation(ny), hat_prolongation(nx)) * free[:, None]
    coarse = p.T @ dense @ p
    r = rng.normal(size=(ny * nx, 3)) * free[:, None]
    expected = np.zeros_like(r)
    for c in range(3):
        a = dense + np.diag(extra[:, c] * free)
        smoother = solver.omega[0] * np.where(free, 1.0 / np.where(free, np.diag(a), 1.0), 0.0)
        e = smoother * r[:, c]
        e = e + p @ np.linalg.solve(coarse, p.T @ (r[:, c] - a @ e))
        expected[:, c] = e + smoother * (r[:, c] - a @ e)
    got = solver.vcycle(r.reshape(ny, nx, 3)).reshape(-1, 3)
    assert np.allclose(got, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
    assert np.all(got[~free] == 0.0)


def random_block_grid_matrix(ny, nx, pinned, seed=0):
    """A random spring network on the Provot stencil with 3x3 blocks (stiff along a
    random direction, soft across, as a Newton Hessian) and masses: the dense (3n, 3n)
    matrix (pinned rows and columns 0) and its block stencil weights (ny, nx, k, 6)."""
    rng = np.random.default_rng(seed)
    n = ny * nx
    dense = np.kron(np.diag(rng.uniform(20.0, 80.0, n)), np.eye(3))
    for j in range(ny):
        for i in range(nx):
            for di, dj in PROVOT[1::2]:
                if 0 <= j + dj < ny and 0 <= i + di < nx:
                    d = rng.normal(size=3)
                    d /= np.linalg.norm(d)
                    block = (rng.uniform(100.0, 1000.0) * np.outer(d, d)
                             + rng.uniform(0.0, 10.0) * (np.eye(3) - np.outer(d, d)))
                    a, b = 3 * (j * nx + i), 3 * ((j + dj) * nx + i + di)
                    for r, c, sign in ((a, a, 1), (b, b, 1), (a, b, -1), (b, a, -1)):
                        dense[r:r + 3, c:c + 3] += sign * block
    free = np.ones(n, dtype=bool)
    free[[j * nx + i for j, i in pinned]] = False
    dense[~np.repeat(free, 3), :] = 0.0
    dense[:, ~np.repeat(free, 3)] = 0.0
    weights = np.zeros((ny, nx, len(PROVOT), 6))
    for j in range(ny):
        for i in range(nx):
            for k, (di, dj) in enumerate(PROVOT):
                if 0 <= j + dj < ny and 0 <= i + di < nx:
                    r, c = 3 * (j * nx + i), 3 * ((j + dj) * nx + i + di)
                    b = dense[r:r + 3, c:c + 3]
                    weights[j, i, k] = b[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]
    return dense, weights, free


def test_block_coarse_operators_are_the_galerkin_products(f64):
    ny, nx = 13, 18
    dense, weights, free = random_block_grid_matrix(ny, nx, pinned=[(0, 0), (0, nx - 1)])
    solver = block_multigrid.BlockGridMultigrid(nx, ny, PROVOT)
    assert solver.shapes == [(13, 18), (7, 10), (4, 6)]
    solver.set_matrix(weights)
    assert np.allclose(galerkin.dense_matrix(weights, PROVOT), dense)
    p = np.kron(np.kron(hat_prolongation(ny), hat_prolongation(nx)), np.eye(3))
    coarse = solver.level_weights(1)
    assert np.allclose(solver.level_weights(0), weights)
    assert np.allclose(galerkin.dense_matrix(coarse, galerkin.coarse_stencil(PROVOT)), p.T @ dense @ p,
                       rtol=0, atol=1e-10 * np.abs(dense).max())
    assert np.allclose(galerkin.galerkin(weights, PROVOT), coarse)
    assert np.allclose(solver.product(np.arange(ny * nx * 3.0).reshape(ny, nx, 3)).ravel(),
                       dense @ np.arange(ny * nx * 3.0))


def vcycle_matrix(solver, free):
    """B on the free degrees of freedom, column by column; pinned entries stay 0."""
    ny, nx = solver.shapes[0]
    dofs = np.flatnonzero(np.repeat(free, 3))
    b = np.zeros((len(dofs), len(dofs)))
    for c, d in enumerate(dofs):
        unit = np.zeros(ny * nx * 3)
        unit[d] = 1.0
        out = solver.vcycle(unit.reshape(ny, nx, 3)).ravel()
        assert np.all(out[~np.repeat(free, 3)] == 0.0)
        b[:, c] = out[dofs]
    return b, dofs


@pytest.mark.slow
def test_block_vcycle_is_symmetric_with_the_spectrum_of_b_a_in_0_1(f64):
    """Symmetric Gauss-Seidel smoothing around an exact coarse solve: B A = I - E^T Q E
    (E the smoother's error propagation, Q an A-orthogonal projector), so B is symmetric
    and the eigenvalues of B A lie in (0, 1], with no smoothing weight to estimate. With
    the coarse levels of another matrix (``build(coarse=False)``, as backward Euler's
    later Newton iterations do) B stays symmetric positive definite."""
    ny, nx = 19, 17
    pinned = [(0, 0), (9, 8)]
    dense, weights, free = random_block_grid_matrix(ny, nx, pinned, seed=5)
    solver = block_multigrid.BlockGridMultigrid(nx, ny, PROVOT)
    assert solver.levels == 3
    solver.set_matrix(weights)
    b, dofs = vcycle_matrix(solver, free)
    assert np.allclose(b, b.T, atol=1e-12 * np.abs(b).max())
    eig = np.linalg.eigvals(b @ dense[np.ix_(dofs, dofs)])
    assert np.abs(eig.imag).max() < 1e-9
    assert eig.real.min() > 0.05 and eig.real.max() < 1.0 + 1e-9, (eig.real.min(), eig.real.max())
    _, other, _ = random_block_grid_matrix(ny, nx, pinned, seed=8)
    solver.w[0].from_numpy(solver.stored_blocks(other))
    solver.build(coarse=False)
    stale, _ = vcycle_matrix(solver, free)
    assert np.allclose(stale, stale.T, atol=1e-12 * np.abs(stale).max())
    assert np.linalg.eigvalsh(0.5 * (stale + stale.T)).min() > 0.0
    assert not np.allclose(stale, b)


@pytest.mark.slow
def test_multigrid_preconditioned_cg_solves_in_a_few_iterations(f64):
    ny, nx = 40, 33
    dense, weights, free = random_block_grid_matrix(ny, nx, pinned=[(0, 0), (0, 32)], seed=6)
    solver = block_multigrid.BlockGridMultigrid(nx, ny, PROVOT)
    solver.set_matrix(weights)
    cg = block_multigrid.GridPCG(solver)
    rhs = np.random.default_rng(7).normal(size=(ny * nx, 3)) * free[:, None]
    solver.load_rhs(rhs.reshape(ny, nx, 3))
    iterations, residual = cg.solve(1e-10, 50)
    x = cg.x.to_numpy()[galerkin.PAD:-galerkin.PAD, galerkin.PAD:-galerkin.PAD].reshape(-1)
    exact = np.zeros(ny * nx * 3)
    dofs = np.repeat(free, 3)
    exact[dofs] = np.linalg.solve(dense[np.ix_(dofs, dofs)], rhs.ravel()[dofs])
    assert residual < 1e-10 and iterations <= 20, iterations     # 16 here: 20 leaves room
    assert np.abs(x - exact).max() < 1e-8 * np.abs(exact).max()
    assert np.all(x[~dofs] == 0.0)


def test_cg_on_an_indefinite_matrix_stops_with_a_descent_direction(f64):
    """CG on a matrix W of its own, preconditioned by the cycle of an SPD A (as backward
    Euler: the exact Hessian, preconditioned by the projected one). W = A + 30 I is solved
    exactly; on W = A - 60 I (indefinite) CG stops at the first direction of
    non-positive curvature with x a descent direction that lowers the quadratic model
    1/2 x.W x - b.x; on W = -A it stops at once with x = B b."""
    ny, nx = 12, 11
    dense, weights, free = random_block_grid_matrix(ny, nx, pinned=[(0, 0)], seed=3)
    solver = block_multigrid.BlockGridMultigrid(nx, ny, PROVOT)
    solver.set_matrix(weights)
    cg = block_multigrid.GridPCG(solver, own_matrix=True)
    dofs = np.repeat(free, 3)
    rhs = np.random.default_rng(4).normal(size=(ny * nx, 3)) * free[:, None]
    eye = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])

    def solve(shift, sign=1.0):
        w = sign * weights
        w[:, :, 0] += shift * free.reshape(ny, nx, 1) * eye
        cg.w.from_numpy(solver.stored_blocks(w))
        solver.load_rhs(rhs.reshape(ny, nx, 3))
        iterations, residual = cg.solve(1e-10, 200)
        x = cg.x.to_numpy()[galerkin.PAD:-galerkin.PAD, galerkin.PAD:-galerkin.PAD].reshape(-1)
        matrix = (sign * dense + shift * np.diag(dofs.astype(float)))[np.ix_(dofs, dofs)]
        return iterations, residual, x, matrix
    iterations, residual, x, matrix = solve(30.0)
    assert residual < 1e-10
    assert np.allclose(x[dofs], np.linalg.solve(matrix, rhs.ravel()[dofs]), rtol=0,
                       atol=1e-8 * np.abs(x).max())
    iterations, residual, x, matrix = solve(-60.0)
    eig = np.linalg.eigvalsh(matrix)
    assert eig.min() < 0.0 < eig.max()
    assert 1 < iterations < 200 and residual > 1e-10
    b, xf = rhs.ravel()[dofs], x[dofs]
    assert b @ xf > 0.0 and 0.5 * xf @ matrix @ xf - b @ xf < 0.0
    assert np.all(x[~dofs] == 0.0)
    iterations, residual, x, _ = solve(0.0, sign=-1.0)
    assert iterations == 1 and residual == 1.0
    assert np.allclose(x, solver.vcycle(rhs.reshape(ny, nx, 3)).ravel(), rtol=0,
                       atol=1e-12 * np.abs(x).max())
