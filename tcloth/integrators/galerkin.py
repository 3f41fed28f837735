"""The NumPy algebra of geometric multigrid on a cloth grid: prolongation, Galerkin
coarse operators P^T A P as fixed combinations of fine stencil weights, stencil products,
dense matrices and the Jacobi smoothing weight. The Taichi cycles (``multigrid.py``,
``block_multigrid.py``) read the tables built here; the tests check them against dense
NumPy.

A matrix on a cloth grid couples each particle with the ends of its springs
(``grid.stencil``). Coarser levels halve the grid in both directions (nodes 2I of the
finer level) with bilinear prolongation P (an even-sized grid gets a coarse node one past
its end); P^T A P stays within a 5 x 5 stencil (21 points for Provot cloth).
"""
import numpy as np

PAD = 2
WPAD = 3          # the block weights' padding: Galerkin sums reach 3 past a coarse node
COARSEST_NODES = 64


def coarse_size(n):
    """Coarse nodes for n fine ones: 2I covers 0 .. n - 1, and one node past an even n."""
    return n // 2 + 1


def prolongation_1d(n_fine):
    """(n_fine, coarse_size(n_fine)) bilinear: fine 2I takes coarse I, an odd node the mean
    of its two coarse neighbours."""
    p = np.zeros((n_fine, coarse_size(n_fine)))
    for f in range(n_fine):
        p[f, f // 2] = 1.0 if f % 2 == 0 else 0.5
        if f % 2:
            p[f, f // 2 + 1] = 0.5
    return p


def apply_stencil(weights, stencil, v):
    """sum_k weights[..., k] v[j + dj_k, i + di_k] on a (ny, nx) grid, zero outside."""
    ny, nx = v.shape
    padded = np.pad(v, PAD)
    out = np.zeros_like(v)
    for k, (di, dj) in enumerate(stencil):
        out += weights[..., k] * padded[PAD + dj:PAD + dj + ny, PAD + di:PAD + di + nx]
    return out


def coarse_stencil(stencil):
    """The offsets P^T A P can couple when A couples ``stencil``: coarse nodes I, K meet
    where fine nodes 2I + u, 2K + w (|u|, |w| <= 1 per axis) are a stencil offset apart,
    so 2 (K - I) = s + (u - w). Within 5 x 5 while the stencil reaches at most 2; the
    Provot stencil and its coarse ones give 21 (no corners: no offset reaches 2 on both
    axes)."""
    offsets = {(di, dj) for si, sj in stencil for di in range(-2, 3) for dj in range(-2, 3)
               if abs(2 * di - si) <= 2 and abs(2 * dj - sj) <= 2}
    return tuple(sorted(offsets, key=lambda o: (o[1], o[0])))


def galerkin_terms(stencil):
    """P^T A P at coarse node (J, I) as sums of fine weights: for each offset of
    ``coarse_stencil(stencil)`` the terms (dj, di, k, c), c times weight k of fine node
    (2J + dj, 2I + di). The fine nodes are the nine P maps node (J, I) to (|di|, |dj| <= 1,
    weight (1 - |di|/2) (1 - |dj|/2)); weight k couples one to fine node b, which P^T maps
    to the coarse node(s) next to it: b/2 when b is even, else both halves at 1/2 (per axis,
    relative to 2J, 2I)."""
    coarse = coarse_stencil(stencil)
    slot = {offset: n for n, offset in enumerate(coarse)}
    terms = [[] for _ in coarse]

    def parents(b):
        return [(b // 2, 1.0)] if b % 2 == 0 else [((b - 1) // 2, 0.5), ((b + 1) // 2, 0.5)]
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            weight = (1.0 - abs(di) / 2) * (1.0 - abs(dj) / 2)
            for k, (si, sj) in enumerate(stencil):
                for ci, wi in parents(di + si):
                    for cj, wj in parents(dj + sj):
                        terms[slot[(ci, cj)]].append((dj, di, k, weight * wi * wj))
    return tuple(tuple(t) for t in terms)


def half_stencil(stencil):
    """The centre and the offsets of a symmetric stencil that point forwards (dj > 0, or
    dj = 0 and di > 0): each coupling once."""
    return ((0, 0),) + tuple(o for o in stencil if o[1] > 0 or (o[1] == 0 and o[0] > 0))


def half_galerkin_terms(stencil):
    """``galerkin_terms`` for blocks stored over ``half_stencil``s: the terms of the coarse
    half's offsets, each reading a stored fine block (a block at offset -s of fine node a
    is the one at offset s of node a - s)."""
    coarse, half = coarse_stencil(stencil), half_stencil(stencil)
    full = galerkin_terms(stencil)
    out = []
    for offset in half_stencil(coarse):
        terms = []
        for dj, di, k, c in full[coarse.index(offset)]:
            si, sj = stencil[k]
            if (si, sj) in half:
                terms.append((dj, di, half.index((si, sj)), c))
            else:
                terms.append((dj + sj, di + si, half.index((-si, -sj)), c))
        out.append(tuple(terms))
    return tuple(out)


def galerkin(weights, stencil):
    """P^T A P as (nyc, nxc, len(coarse_stencil(stencil)), ...) weights, from fine weights
    (ny, nx, len(stencil), ...): scalars, or blocks in a trailing axis."""
    ny, nx = weights.shape[:2]
    cy, cx = coarse_size(ny), coarse_size(nx)
    padded = np.pad(weights, [(PAD, PAD), (PAD, PAD)] + [(0, 0)] * (weights.ndim - 2))
    terms = galerkin_terms(stencil)
    out = np.zeros((cy, cx, len(terms)) + weights.shape[3:])
    for s, slot_terms in enumerate(terms):
        for dj, di, k, c in slot_terms:
            out[:, :, s] += c * padded[PAD + dj:PAD + dj + 2 * cy:2,
                                       PAD + di:PAD + di + 2 * cx:2, k]
    return out


def symmetric_blocks(w6):
    """(..., 6) symmetric 3x3 blocks (xx, yy, zz, xy, xz, yz) as (..., 3, 3)."""
    xx, yy, zz, xy, xz, yz = np.moveaxis(w6, -1, 0)
    return np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1),
                     np.stack([xz, yz, zz], -1)], -2)


def dense_matrix(weights, stencil):
    """The matrix of a stencil operator on a (ny, nx) grid, rows j * nx + i: (n, n) from
    scalar weights (ny, nx, k), (3n, 3n) from symmetric blocks (ny, nx, k, 6) (rows
    3 (j * nx + i) + component)."""
    ny, nx = weights.shape[:2]
    blocks = symmetric_blocks(weights) if weights.ndim == 4 else weights[..., None, None]
    b = blocks.shape[-1]
    n = ny * nx
    a = np.zeros((n, n, b, b))
    jj, ii = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    for k, (di, dj) in enumerate(stencil):
        inside = (0 <= jj + dj) & (jj + dj < ny) & (0 <= ii + di) & (ii + di < nx)
        rows = (jj * nx + ii)[inside]
        a[rows, rows + dj * nx + di] += blocks[inside, k]
    return a.transpose(0, 2, 1, 3).reshape(n * b, n * b)


def smoothing_weight(weights, stencil, iterations=30):
    """The Jacobi weight 4 / (3 lambda), lambda the largest eigenvalue of D^-1 A by power
    iteration (rows with a zero diagonal are inactive), raised by 5 % against an
    underestimate."""
    diag = weights[..., stencil.index((0, 0))]
    inv = np.where(diag > 0, 1.0 / np.where(diag > 0, diag, 1.0), 0.0)
    v = np.random.default_rng(0).uniform(-1.0, 1.0, diag.shape) * (diag > 0)
    lam = 1.0
    for _ in range(iterations):
        w = inv * apply_stencil(weights, stencil, v)
        lam = np.abs(w).max() / max(np.abs(v).max(), 1e-300)
        v = w / max(np.abs(w).max(), 1e-300)
    return 4.0 / (3.0 * 1.05 * lam)
