"""Springs that break (``Scene.set_tearing``): the check at the end of every step, what
broke, and the cloth surface that follows it (``docs/tearing.md``).

After a step is accepted (the instability test passed, so a split step's pieces each
count as a step), one kernel walks the tearable springs: a spring that still holds and
whose strain (|x_ij| - l0) / l0 is above ``max_strain`` breaks: its k_s and k_d become 0
in the model's fields (force, energy, Hessian blocks and XPBD's constraint vanish in every
solver, nothing compiles again) and its row is appended to the model's ``broken`` list.
The kernel's count is read back once a step; only where it grew does Python do anything:
the integrator drops what it built from the spring values (projective's constant matrix),
the energy budget takes a new baseline (a break removes the spring's elastic energy and
adds none), the surface's version moves on and the wind blows on what holds.
"""
import numpy as np
import taichi as ti

from ..runtime import serial


@ti.func
def tear_springs(data, x, pairs, rest):
    """Break the tearable springs that hold and are strained past ``data.max_strain``;
    returns how many broke now."""
    before = data.torn[None]
    stretch = ti.static(1.0 + data.max_strain)
    ti.loop_config(serialize=ti.static(serial(data.rows)))
    for k in range(data.count):
        s = k
        if ti.static(not data.every):
            s = data.rows[k]
        if data.alive[s] != 0:
            i, j = pairs[s][0], pairs[s][1]
            d = x[i] - x[j]
            longest = stretch * rest[s]
            if d.dot(d) > longest * longest:
                data.alive[s] = 0
                data.ks[s] = 0.0
                data.kd[s] = 0.0
                if ti.static(data.gridded):
                    slot = data.grid_slot[s]
                    if slot >= 0:
                        data.grid_alive[slot // 6, slot % 6] = 0
                data.broken[ti.atomic_add(data.torn[None], 1)] = s
    return data.torn[None] - before


@ti.kernel
def _tear(tearing: ti.template(), x: ti.template()) -> ti.i32:
    """``tear_springs`` at positions x; returns how many springs have broken in all."""
    tearing.tear(x)
    return tearing.data.torn[None]


@ti.data_oriented
class Tearing:
    """A simulator's tearing: the check after each step (``after_step``), what broke
    (``torn``) and the cloth triangles that still hold (``surface``)."""

    def __init__(self, model):
        self.model = model
        self.data = model.tearing
        self.version = 0             # moves on with every step that breaks a spring
        self._surface = None

    @ti.func
    def tear(self, x):
        """``tear_springs`` as a ``ti.func`` (the simulator's batches); how many broke."""
        return tear_springs(self.data, x, self.model.spring_pairs, self.model.spring_rest)

    def batch_obstacle(self):
        if self.model.wind is not None or self.model.bending is not None:
            return "the wind's triangles and the hinges follow a tear from Python"
        if not serial(self.data.rows):
            return f"tearing's {self.data.count} springs run on several threads"
        return None

    def after_step(self, x):
        """Break the springs strained past the threshold at positions ``x`` (the accepted
        state); whether any broke."""
        if not self.data.count:
            return False
        return self._follow(_tear(self, x))

    def sync(self):
        """Take in what broke in the steps of a batch; whether any did."""
        return self._follow(self.data.torn[None])

    def _follow(self, count):
        data = self.data
        if count == len(data.rows_broken):
            return False
        data.rows_broken = data.broken.to_numpy()[:count].astype(np.int64)
        self._moved()
        return True

    def _moved(self):
        """The surface changed: its version moves on, the wind blows on what holds, and
        the hinges of the torn triangles bend no more."""
        self.version += 1
        self._surface = None
        model = self.model
        if model.wind is not None:
            model.wind.hold(self.surface())
        if model.bending is not None:
            model.bending.hold(model.scene.springs["pairs"][self.torn()],
                               model.scene.bending["rigidity"])

    def mark(self, synced=False):
        """How many springs have broken in all (``rollback``'s argument); synced: as taken
        in last (``after_step``, ``sync``: no read from the device), right where nothing
        stepped since."""
        return len(self.data.rows_broken) if synced else int(self.data.torn[None])

    def rollback(self, mark):
        """Mend the springs that broke after ``mark`` (a batch's steps taken again from
        their start): held again, with the scene's stiffness and damping."""
        data = self.data
        count = int(data.torn[None])
        if count == mark:
            return
        rows = data.broken.to_numpy()[mark:count].astype(np.int64)
        springs = self.model.scene.springs
        ids = self.model.spring_order[rows]
        data.mend_rows(rows, springs["stiffness"][ids], springs["damping"][ids])
        data.torn[None] = mark
        data.rows_broken = data.rows_broken[:min(mark, len(data.rows_broken))]
        self._moved()

    def mend(self):
        """Every spring holds again (``Simulator.reset``)."""
        self.data.mend()
        self._moved()

    def torn(self):
        """(B,) int64: the scene spring ids that broke, in the order they did."""
        return self.model.spring_order[self.data.rows_broken].astype(np.int64)

    def restore(self, spring_ids):
        """Break the scene springs ``spring_ids`` (in that order), as a checkpoint holds
        them: the same fields as if they had broken in this run."""
        position = np.empty(len(self.model.spring_order), dtype=np.int64)
        position[self.model.spring_order] = np.arange(len(self.model.spring_order))
        self.data.break_rows(position[np.asarray(spring_ids, dtype=np.int64)])
        self._moved()

    def surface(self):
        """(T,) bool over ``scene.triangles``: the triangles that hold, those with no
        broken spring along an edge (kept until the next break)."""
        if self._surface is None:
            self._surface = holding_triangles(self.model.scene, self.torn())
        return self._surface


def holding_triangles(scene, torn):
    """(T,) bool over ``scene.triangles``: True where no spring of ``torn`` (scene spring
    ids) joins two corners of the triangle."""
    triangles = scene.triangles
    if not len(torn):
        return np.ones(len(triangles), dtype=bool)
    n = scene.num_particles
    pairs = np.sort(scene.springs["pairs"][np.asarray(torn)], axis=1)
    cut = pairs[:, 0] * n + pairs[:, 1]
    held = np.ones(len(triangles), dtype=bool)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        edge = np.sort(triangles[:, [a, b]], axis=1)
        held &= ~np.isin(edge[:, 0] * n + edge[:, 1], cut)
    return held
