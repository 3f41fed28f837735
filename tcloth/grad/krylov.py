"""Flexible GMRES (Saad 1993, "A flexible inner-outer preconditioned GMRES algorithm"):
the adjoint solve of a step whose Jacobian is not symmetric (projective dynamics' residual:
the springs' damping along their current direction). The preconditioner is applied to each
direction once and the results kept, so it may also be an inner iterative solve stopped at
a tolerance, which changes from one application to the next.
"""
import numpy as np


def fgmres(operator, precondition, b, tol, restart=40, max_iterations=400):
    """Solve operator(x) = b (NumPy vectors) to |b - operator(x)| <= tol |b|, right-
    preconditioned by ``precondition`` (any approximate inverse, applied afresh to each
    direction and stored), restarted every ``restart`` iterations. Returns (x, iterations,
    the true relative residual)."""
    norm_b = float(np.linalg.norm(b))
    x = np.zeros_like(b)
    if norm_b == 0.0:
        return x, 0, 0.0
    iterations, r = 0, b.copy()
    while True:
        beta = float(np.linalg.norm(r))
        if beta <= tol * norm_b or iterations >= max_iterations:
            return x, iterations, beta / norm_b
        basis, directions = [r / beta], []
        hessenberg = np.zeros((restart + 1, restart))
        rhs = np.zeros(restart + 1)
        rhs[0] = beta
        for j in range(restart):
            z = precondition(basis[j])
            w = operator(z)
            directions.append(z)
            for i in range(j + 1):          # modified Gram-Schmidt
                hessenberg[i, j] = w @ basis[i]
                w = w - hessenberg[i, j] * basis[i]
            hessenberg[j + 1, j] = np.linalg.norm(w)
            iterations += 1
            y, *_ = np.linalg.lstsq(hessenberg[:j + 2, :j + 1], rhs[:j + 2], rcond=None)
            estimate = np.linalg.norm(rhs[:j + 2] - hessenberg[:j + 2, :j + 1] @ y)
            if (estimate <= tol * norm_b or hessenberg[j + 1, j] == 0.0
                    or iterations >= max_iterations):
                break
            basis.append(w / hessenberg[j + 1, j])
        x = x + np.stack(directions, axis=1) @ y
        r = b - operator(x)
