"""The explicit stability limit of a scene's springs, computed with NumPy from the scene
alone (independently of the simulator's force code).

For the undamped linearised system M a = -K x, symplectic Euler (and Verlet) is stable
while dt < 2 / omega_max, omega_max^2 the largest eigenvalue of M^-1 K; forward Euler is
unstable at every dt without damping.
"""
import numpy as np

DENSE_BELOW = 3000


def _blocks(scene):
    """(pairs, (M,3,3) Hessian blocks) of the spring energy at the scene's positions:
    k [d d^T + (1 - l0 / l)(I - d d^T)], d the unit spring direction."""
    springs = scene.springs
    pairs = springs["pairs"]
    d = scene.positions[pairs[:, 0]] - scene.positions[pairs[:, 1]]
    # a seam's ends may coincide: rest length 0 makes its block k I whatever d
    length = np.linalg.norm(d, axis=1)
    length = np.where(length > 0.0, length, 1.0)
    d = d / length[:, None]
    dd = d[:, :, None] * d[:, None, :]
    geometric = (1.0 - springs["rest_length"] / length)[:, None, None]
    blocks = springs["stiffness"][:, None, None] * (dd + geometric * (np.eye(3) - dd))
    return pairs, blocks


def omega_max(scene, iterations=500, seed=0):
    """sqrt of the largest eigenvalue of M^-1 K over the free particles (rad/s), K the
    Hessian of the spring energy at the scene's positions. Exact (dense eigenvalues) up
    to DENSE_BELOW free coordinates; above, the Rayleigh quotient after ``iterations``
    power iterations (a lower bound that converges from below)."""
    pairs, blocks = _blocks(scene)
    n = len(scene.positions)
    free = ~np.asarray(scene.pinned, dtype=bool)
    scale = np.where(free, 1.0 / np.sqrt(scene.masses), 0.0)
    if len(pairs) == 0 or not free.any():
        return 0.0
    if 3 * free.sum() <= DENSE_BELOW:
        k = np.zeros((3 * n, 3 * n))
        for (i, j), b in zip(pairs, blocks):
            for a, c, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
                k[3 * a:3 * a + 3, 3 * c:3 * c + 3] += sign * b
        s = np.repeat(scale, 3)
        keep = np.repeat(free, 3)
        reduced = (k * s[:, None] * s[None, :])[np.ix_(keep, keep)]
        return float(np.sqrt(max(np.linalg.eigvalsh(reduced)[-1], 0.0)))
    i, j = pairs[:, 0], pairs[:, 1]

    def product(v):
        u = v * scale[:, None]
        f = np.einsum("mab,mb->ma", blocks, u[i] - u[j])
        out = np.zeros_like(v)
        np.add.at(out, i, f)
        np.add.at(out, j, -f)
        return out * scale[:, None]
    v = np.random.default_rng(seed).standard_normal((n, 3)) * free[:, None]
    for _ in range(iterations):
        v = product(v / np.linalg.norm(v))
    v /= np.linalg.norm(v)
    return float(np.sqrt(max(np.sum(v * product(v)), 0.0)))


def explicit_dt_limit(scene):
    """2 / omega_max, s: symplectic Euler's stability limit without damping (inf without
    springs)."""
    w = omega_max(scene)
    return 2.0 / w if w > 0 else float("inf")


def gershgorin_dt(scene):
    """2 / omega_bound, s: a lower bound on symplectic Euler's stability limit from
    Gershgorin's theorem (no eigenvalue solve, so cheap at any size): omega^2 <= max over
    free particles i of sum over i's springs of k_s (1/m_i + 1/sqrt(m_i m_j)), the row sums
    of M^-1/2 K M^-1/2 at rest length. Colliders and self-contact add their penalty
    stiffness k / m_i (a particle pressed by one contact at a time). inf without springs
    or contacts."""
    m = scene.masses
    free = ~np.asarray(scene.pinned, dtype=bool)
    rows = np.zeros(len(m))
    springs = scene.springs
    if len(springs["pairs"]):
        i, j = springs["pairs"][:, 0], springs["pairs"][:, 1]
        k = springs["stiffness"]
        cross = k / np.sqrt(m[i] * m[j])
        np.add.at(rows, i, k / m[i] + cross)
        np.add.at(rows, j, k / m[j] + cross)
    contact = max([c["stiffness"] for c in scene.colliders], default=0.0)
    if scene.self_collision is not None:
        own = scene.self_collision["stiffness"]
        contact = max(contact, own if own is not None else
                      scene.mean_stiffness("structural") or 0.0)
    rows += contact / m
    bound = rows[free].max() if free.any() else 0.0
    return 2.0 / np.sqrt(bound) if bound > 0 else float("inf")
