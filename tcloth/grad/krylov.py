"""Flexible GMRES (Saad 1993, "A flexible inner-outer preconditioned GMRES algorithm"):
the adjoint solve of a step whose Jacobian is not symmetric (projective dynamics' residual:
the springs' damping along their current direction). The preconditioner is applied to each
direction once and the results kept, so it may also be an inner iterative solve stopped at
a tolerance, which changes from one application to the next.

The basis is orthogonalised by classical Gram-Schmidt done twice (two matrix products a
direction, as accurate as the modified one) and the small least-squares problem reduced
by Givens rotations as it grows, so an iteration costs O(j n) in NumPy's products and
O(j) scalars, not a least-squares solve. Restarts are what stall it: on projective
dynamics' landing steps (a 32 x 32 drape at dt 1/60) restarting every 40 directions
left relative residuals of 0.1 to 0.7 after 500 iterations, where the unrestarted
iteration reached 1e-8 in 58 to 360; the basis is kept up to BASIS_BYTES.
"""
import numpy as np

# the memory the basis and its preconditioned directions may take (restart = this / 16 n)
BASIS_BYTES = 64 << 20


def fgmres(operator, precondition, b, tol, restart=None, max_iterations=400):
    """Solve operator(x) = b (NumPy vectors) to |b - operator(x)| <= tol |b|, right-
    preconditioned by ``precondition`` (any approximate inverse, applied afresh to each
    direction and stored), restarted every ``restart`` iterations (default: as many as
    BASIS_BYTES holds, at most ``max_iterations``). Returns (x, iterations, the true
    relative residual)."""
    norm_b = float(np.linalg.norm(b))
    x = np.zeros_like(b)
    if norm_b == 0.0:
        return x, 0, 0.0
    if restart is None:
        restart = BASIS_BYTES // (2 * b.size * b.itemsize)
    restart = max(1, min(int(restart), max_iterations))
    basis = np.empty((restart + 1, b.size))
    directions = np.empty((restart, b.size))
    iterations, r = 0, b.copy()
    while True:
        beta = float(np.linalg.norm(r))
        if beta <= tol * norm_b or iterations >= max_iterations:
            return x, iterations, beta / norm_b
        basis[0] = r / beta
        triangle, rotations = np.zeros((restart, restart)), np.zeros((restart, 2))
        rhs = np.zeros(restart + 1)
        rhs[0] = beta
        for j in range(restart):
            directions[j] = precondition(basis[j])
            w = operator(directions[j])
            column = np.zeros(j + 2)
            for _ in range(2):              # classical Gram-Schmidt, twice
                c = basis[:j + 1] @ w
                w = w - c @ basis[:j + 1]
                column[:j + 1] += c
            column[j + 1] = norm_w = float(np.linalg.norm(w))
            for i in range(j):              # the earlier rotations, then this column's own
                cos, sin = rotations[i]
                column[i], column[i + 1] = (cos * column[i] + sin * column[i + 1],
                                            cos * column[i + 1] - sin * column[i])
            radius = float(np.hypot(column[j], column[j + 1]))
            cos, sin = (column[j] / radius, column[j + 1] / radius) if radius else (1.0, 0.0)
            rotations[j] = cos, sin
            triangle[:j + 1, j] = column[:j + 1]
            triangle[j, j] = radius
            rhs[j], rhs[j + 1] = cos * rhs[j], -sin * rhs[j]
            iterations += 1
            if (abs(rhs[j + 1]) <= tol * norm_b or norm_w == 0.0
                    or iterations >= max_iterations):
                break
            basis[j + 1] = w / norm_w
        k = j + 1
        y = np.linalg.solve(triangle[:k, :k], rhs[:k]) if triangle[k - 1, k - 1] else \
            np.linalg.lstsq(triangle[:k, :k], rhs[:k], rcond=None)[0]
        x = x + y @ directions[:k]
        r = b - operator(x)
