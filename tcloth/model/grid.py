"""The layout of a regular cloth grid: which springs each particle owns, the neighbour
pattern a grid matrix couples, and the springs' rest lengths. The spring stencil
(``terms/springs.py``) and the multigrid solvers (``integrators/``) both read it.

Particle (i, j) of a grid has id ``offset + j * nx + i``. Each Provot family has four
springs at a particle; the particle owns the two towards (i + di, j + dj) for the offsets
in ``OWNED`` and shares the other two with the neighbours that own them.
"""
from dataclasses import dataclass

import numpy as np
import taichi as ti

from .. import runtime

FAMILIES = ("structural", "shear", "flexion")

# Grid springs by family: the two a particle (i, j) owns, to (i + di, j + dj).
OWNED = (((1, 0), (0, 1)),       # structural
         ((1, 1), (-1, 1)),      # shear
         ((2, 0), (0, 2)))       # flexion


@dataclass(frozen=True)
class GridBlock:
    """A regular cloth grid whose springs are evaluated by a neighbour stencil.

    offset: id of particle (i=0, j=0); ids run row by row (id = offset + j*nx + i).
    dx, dy: rest spacing (m). Each family is (k_s, k_d) or None.
    """
    offset: int
    nx: int
    ny: int
    dx: float
    dy: float
    structural: tuple
    shear: tuple
    flexion: tuple

    @property
    def families(self):
        """Static flags (structural, shear, flexion): which families exist."""
        return (self.structural is not None, self.shear is not None, self.flexion is not None)

    def covers(self, particle_count):
        """True when the grid holds every particle of the scene."""
        return self.offset == 0 and self.nx * self.ny == particle_count

    def owned_slots(self, pairs, kinds):
        """(M,) int64: for springs ``pairs`` (M, 2) of ``kinds`` (codes, ``FAMILIES``'
        order), the stencil slot that evaluates each, p * 6 + 2 family + s for the
        particle p that owns it as ``OWNED[family][s]``; -1 for a spring not of this grid
        (its ends elsewhere, or another kind)."""
        pairs = np.asarray(pairs, dtype=np.int64)
        slots = np.full(len(pairs), -1, dtype=np.int64)
        local = pairs - self.offset
        inside = np.all((local >= 0) & (local < self.nx * self.ny), axis=1)
        j, i = np.divmod(local, self.nx)
        for fam in range(len(FAMILIES)):
            for s, (di, dj) in enumerate(OWNED[fam]):
                for a, b in ((0, 1), (1, 0)):
                    hit = inside & (kinds == fam) & (i[:, b] - i[:, a] == di) & \
                        (j[:, b] - j[:, a] == dj)
                    slots[hit] = (pairs[hit, a] * 6) + 2 * fam + s
        return slots


@ti.data_oriented
class GridTable:
    """The grids' numbers as fields for the kernels.

    Attributes:
        ints: shape (grids,) of (offset, nx, ny).
        reals: shape (grids,) of (dx, dy, k_s structural, shear, flexion, k_d structural,
            shear, flexion); an absent family has k_s = k_d = 0.
    """

    def __init__(self, grids):
        count = max(len(grids), 1)
        self.ints = ti.Vector.field(3, ti.i32, shape=count)
        self.reals = ti.Vector.field(8, runtime.real(), shape=count)
        if grids:
            self.ints.from_numpy(np.array([(g.offset, g.nx, g.ny) for g in grids],
                                          dtype=np.int32))
        self.upload(grids)

    def upload(self, grids):
        """Write the grids' spacings and spring parameters into ``reals``."""
        if grids:
            self.reals.from_numpy(np.array(
                [[g.dx, g.dy] + [0.0 if p is None else p[c] for c in (0, 1)
                                 for p in (g.structural, g.shear, g.flexion)]
                 for g in grids], dtype=runtime.numpy_real()))


def stencil(families):
    """The offsets (di, dj) a Provot grid's matrix couples: itself and both ends of each
    owned spring of the families present."""
    offsets = [(0, 0)]
    for fam, present in enumerate(families):
        if present:
            for di, dj in OWNED[fam]:
                offsets += [(di, dj), (-di, -dj)]
    return tuple(offsets)


def family_of(di, dj):
    """The spring family (index into ``FAMILIES``) of grid offset (di, dj)."""
    return next(f for f, owned in enumerate(OWNED) if (di, dj) in owned or (-di, -dj) in owned)


@ti.func
def rest_lengths(g):
    """The grid's cell sides and diagonal from its ``GridTable.reals`` row g."""
    dx, dy = g[0], g[1]
    return ti.Vector([dx, dy, ti.sqrt(dx * dx + dy * dy)])


@ti.func
def rest_length(rest, di: ti.template(), dj: ti.template()):
    """The rest length of the grid spring to offset (di, dj) from ``rest_lengths``:
    a cell diagonal (shear), or one or two cell sides (structural, flexion)."""
    length = rest[2]
    if ti.static(dj == 0):
        length = ti.static(abs(di)) * rest[0]
    elif ti.static(di == 0):
        length = ti.static(abs(dj)) * rest[1]
    return length


@ti.func
def stiffness(g, fam: ti.template()):
    """(k_s, k_d) of family ``fam`` from a ``GridTable.reals`` row."""
    return g[2 + fam], g[5 + fam]
