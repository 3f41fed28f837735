"""The candidate list: the rows every consumer of the contact set reads (``ContactList``),
and a contact's gap at given positions (``gap``).

A row is a point-triangle or edge-edge pair (four particle ids and the kind) and whether
it repels (0 for a pair that touches by construction: no penalty, but the guard keeps it
from crossing). Two searches fill such lists, and only the contact stage
(``stage.py``) runs them: the proximity list (``broad.py``) and a step's swept-box
candidates (``swept.py``). Its consumers keep their columns per row themselves: the
guard's separating planes and the projection's marks (``guard.Planes``, which the stage
keeps beside each list), the contact law's lagged values for backward Euler
(``terms/contact_lag.Lagged``).

A contact joins four particles x_k with weights alpha_k so that the gap between the two
closest points is g = sum_k alpha_k x_k (``geometry/proximity.py``): point-triangle (a
particle against a cloth triangle, alpha = (1, -w_a, -w_b, -w_c)) and edge-edge (two
cloth edges or rope segments, alpha = (1 - s, s, -(1 - u), -u)).
"""
import numpy as np
import taichi as ti

from ..geometry.proximity import contact_weights


@ti.func
def gap(ids, kind, x):
    """(alpha, g) of a contact at positions x."""
    alpha = contact_weights(kind, x[ids[0]], x[ids[1]], x[ids[2]], x[ids[3]])
    g = ti.Vector.zero(float, 3)
    for k in ti.static(range(4)):
        g += alpha[k] * x[ids[k]]
    return alpha, g


@ti.data_oriented
class ContactList:
    """Candidate contacts (ids (4,), kind and whether they repel, per row) of capacity
    ``capacity``. Consumers keep their own columns per row: the guard's planes
    (``guard.Planes``, beside each of the stage's lists) and the contact law's lagged
    values (``terms.contact_lag.Lagged``)."""

    def __init__(self, table, inv_mass, capacity):
        self.table, self.inv_mass = table, inv_mass
        self.capacity = capacity
        self.ids = ti.Vector.field(4, ti.i32, shape=capacity)
        self.kind = ti.field(ti.i32, shape=capacity)
        # 0 for a pair that touches by construction (mesh neighbours across its sides):
        # no penalty, but the guard keeps it from crossing
        self.repels = ti.field(ti.u8, shape=capacity)

    def upload(self, ids, kinds):
        """Rows from NumPy (ids (r, 4), kinds (r,), r <= capacity), each repelling; the
        rows past them zero and not repelling."""
        r, capacity = len(kinds), self.capacity
        padded = np.zeros((capacity, 4), dtype=np.int32)
        padded[:r] = ids
        self.ids.from_numpy(padded)
        self.kind.from_numpy(np.pad(np.asarray(kinds, dtype=np.int32), (0, capacity - r)))
        self.repels.from_numpy((np.arange(capacity) < r).astype(np.uint8))

    @ti.func
    def gap(self, ids, kind, x):
        """(alpha, g) of a contact at positions x."""
        return gap(ids, kind, x)

    @ti.func
    def inverse_mass(self, ids, alpha):
        """sum_k alpha_k^2 / m_k: the contact's inverse effective mass."""
        w = 0.0
        for k in ti.static(range(4)):
            w += alpha[k] * alpha[k] * self.inv_mass[ids[k]]
        return w
