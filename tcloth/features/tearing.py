"""``Scene.set_tearing`` and the model's tearable springs (``sim/tearing.py`` breaks them
at the end of every step; ``docs/tearing.md`` says how the rest of the simulator follows).

A spring breaks when its strain (|x_ij| - l0) / l0 passes ``max_strain`` at a step's end.
A broken spring's stiffness and damping are 0 in the model's fields from then on, so its
force, energy, Hessian blocks and constraint are nothing in every solver without a kernel
compiled again, and its ``alive`` flag is 0 (the strain diagnostics and the strain
limiter skip it); a cloth grid's stencil, which reads the grid's one stiffness, reads
a flag per stencil slot too (``grid_alive``).
"""
import numpy as np
import taichi as ti

from ..errors import SceneError
from ..scene.scene import KIND_CODE, SPRING_KINDS
from ..validate import as_scalar
from .base import Feature

# the features whose elements span several springs' particles and do not yet follow a tear
UNCUT = {"membrane": "the membrane",
         "pressure": "pressure's chambers", "self_collision": "self-collision"}


@ti.data_oriented
class TearingData:
    """The model's tearing (``model.tearing``).

    Attributes:
        count: the number of tearable springs R.
        rows: (max(R, 1),) i32: their model rows (``Model.spring_order``); every: whether
            they are all the model's rows (then row k is rows[k] = k, not read).
        max_strain: the strain past which a spring breaks.
        alive: (max(spring_count, 1),) i32 per model row: 1 while the spring holds, 0 once
            it broke (every row starts at 1).
        broken: (max(R, 1),) i32: the model rows in the order they broke; ``torn`` of them
            so far (a 0-d i32 field, counted by the tearing kernel).
        rows_broken: the host's copy of broken[:torn] (NumPy int64), the rows whose k_s
            and k_d stay 0 when the model's spring values are uploaded again.
        ks, kd: the model's spring stiffness and damping fields (a break zeroes a row's).
        gridded: whether the model has cloth grids, whose springs the stencil evaluates
            with the grid's one stiffness: then grid_alive, (particle_count, 6) i32, is 1
            at the stencil slots (``GridBlock.owned_slots``) of the springs that hold, and
            grid_slot, (max(spring_count, 1),) i32, each row's slot (-1: a listed spring).
            Without grids both are (1,)-sized and unused.
    """

    def __init__(self, model, rows, max_strain):
        self.count = len(rows)
        self.every = len(rows) == model.spring_count
        self.rows = ti.field(ti.i32, shape=max(len(rows), 1))
        if len(rows):
            self.rows.from_numpy(rows.astype(np.int32))
        self.max_strain = max_strain
        self.alive = ti.field(ti.i32, shape=max(model.spring_count, 1))
        self.alive.fill(1)
        self.broken = ti.field(ti.i32, shape=max(len(rows), 1))
        self.torn = ti.field(ti.i32, shape=())
        self.rows_broken = np.zeros(0, dtype=np.int64)
        self.ks, self.kd = model.spring_ks, model.spring_kd
        self.gridded = bool(model.grids)
        n = model.particle_count if self.gridded else 1
        self.grid_alive = ti.field(ti.i32, shape=(n, 6))
        self.grid_alive.fill(1)
        self.grid_slot = ti.field(ti.i32, shape=max(model.spring_count, 1) if self.gridded
                                  else 1)
        if self.gridded:
            springs = model.scene.springs
            pairs = springs["pairs"][model.spring_order]
            kinds = springs["kind"][model.spring_order]
            slots = np.full(len(pairs), -1, dtype=np.int64)
            for grid in model.grids:
                slots = np.maximum(slots, grid.owned_slots(pairs, kinds))
            self.grid_slot.from_numpy(slots.astype(np.int32))

    def mend(self):
        """Every spring holds again (the spring values are then uploaded anew)."""
        self.alive.fill(1)
        self.grid_alive.fill(1)
        self.torn[None] = 0
        self.rows_broken = np.zeros(0, dtype=np.int64)

    def _flag(self, rows, value):
        """``alive`` (and the grid slots' flags) of model rows ``rows`` set to value."""
        alive = self.alive.to_numpy()
        alive[rows] = value
        self.alive.from_numpy(alive)
        if self.gridded:
            slots = self.grid_slot.to_numpy()[rows]
            grid_alive = self.grid_alive.to_numpy()
            grid_alive[np.divmod(slots[slots >= 0], 6)] = value
            self.grid_alive.from_numpy(grid_alive)

    def mend_rows(self, rows, stiffness, damping):
        """Model rows ``rows`` hold again, with k_s ``stiffness`` and k_d ``damping``."""
        self._flag(rows, 1)
        for field, value in ((self.ks, stiffness), (self.kd, damping)):
            values = field.to_numpy()
            values[rows] = value
            field.from_numpy(values)

    def break_rows(self, rows):
        """Break model rows ``rows`` (as the tearing kernel would, all at once)."""
        self._flag(rows, 0)
        broken = self.broken.to_numpy()
        broken[:len(rows)] = rows
        self.broken.from_numpy(broken)
        self.torn[None] = len(rows)
        self.rows_broken = np.asarray(rows, dtype=np.int64)
        self.zero_broken()

    def zero_broken(self):
        """k_s = k_d = 0 on the broken rows (after the spring values were uploaded)."""
        if len(self.rows_broken):
            for field in (self.ks, self.kd):
                values = field.to_numpy()
                values[self.rows_broken] = 0.0
                field.from_numpy(values)


class TearingFeature(Feature):
    """``Scene.set_tearing``; the model's ``TearingData``."""
    name, method = "tearing", "set_tearing"
    live = True

    def set(self, scene, max_strain=0.5, families=None):
        """Springs that break: a spring whose strain (length - rest) / rest passes
        ``max_strain`` at the end of a step breaks for good (no force, energy or
        constraint from then on); ``Simulator.torn()`` lists those that did.

        A cloth torn along a line of broken springs comes apart there: its triangles with a
        broken spring along an edge are no longer drawn or exported (``docs/tearing.md``).

        Args:
            max_strain: > 0 (0.5: a spring breaks past 1.5 times its rest length).
            families: None (every spring), or a tuple of spring kinds from
                ("structural", "shear", "flexion", "custom") that tear.
        """
        max_strain = as_scalar("max_strain", max_strain, 0.0, strict=True)
        if families is not None:
            names = (families,) if isinstance(families, str) else tuple(families)
            if not names or any(k not in KIND_CODE for k in names) or \
                    len(set(names)) != len(names):
                raise SceneError(f"families must be None or distinct names from "
                                 f"{SPRING_KINDS} (got {families!r})")
            families = list(names)
        return {"max_strain": max_strain, "families": families}

    def build(self, model, value):
        """The tearable springs' model rows (``TearingData``); a scene feature whose
        elements a tear does not cut yet is refused."""
        uncut = [label for name, label in UNCUT.items() if getattr(model, name) is not None]
        if uncut:
            raise SceneError(f"tearing does not cut {uncut[0]} yet: a scene with "
                             f"Scene.set_tearing cannot have {', '.join(uncut)}")
        kinds = model.scene.springs["kind"][model.spring_order]
        families = value["families"]
        tearable = (np.ones(len(kinds), bool) if families is None else
                    np.isin(kinds, [KIND_CODE[k] for k in families]))
        return TearingData(model, np.flatnonzero(tearable), value["max_strain"])

    def refresh(self, data, value):
        """The spring values were uploaded again: broken springs stay broken."""
        data.zero_broken()


TEARING = TearingFeature()
