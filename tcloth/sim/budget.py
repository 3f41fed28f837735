"""The energy budget: the physical half of the instability test.

A step is bad when it leaves a non-finite value or the user's bounds (``Simulator``'s
position_bound, velocity_bound and strain_bound), or when it leaves the scene with more
energy than it can supply. After the *baseline* (the simulator's start, ``reset``,
``set_state``, a live change, a grab, a loaded checkpoint) at time t_b, with total energy
E_b = S_b + P_b split into S = kinetic + gravity (a sum over particles) and P = the energy
stored in everything else (springs, hinges, the membrane, pressure, contacts,
self-contacts, the grab spring, attraction), every step is checked against

    S(t) + P(t) - P_min <= limit(t) = E_b - P_min + margin + inflow + gain (t - t_b)
                                      + stretch (t - t_b)^2,

where P_min is P's lower bound, the sum of the scene features' ``floor``s (0 but for
softened attraction and pressure; a feature without one, such as unsoftened attraction
or a gas without ambient pressure, turns the budget off), and the rest bounds what the
scene's sources can add (damping, friction and drag only take energy away):

  - margin = KE_b + max(P_b, 0) + M |g| L + M/2 (1 m/s)^2: the integrator's own energy
    error (symplectic Euler's oscillates around the true energy; strain limiting and
    projections move particles) may not exceed the scene's energy scale, which is the
    motion it has, what its springs hold, its weight over its size L (the diagonal of the
    particles' bounding box at the baseline), and at least M moving at 1 m/s;
  - inflow = 2 M (u + w)^2: moving colliders and moving pinned particles (fastest speed u)
    can throw the cloth at up to twice their speed, and wind (fastest speed w, gust
    included; a callable gust's fastest value so far) can carry it at about its own;
  - gain = M |g| u_up: a collider or pinned particle moving up at u_up can lift the cloth;
  - stretch = K u_pin^2 / 2: pinned particles moving at u_pin stretch the springs K that
    join them (sum of k_s) without bound.
M is the free particles' mass. Attraction without softening has no lower bound
(P_min = -inf): such a scene is checked for finite values and the user's bounds only.

Counting P matters where a solver tears a cloth without making it move fast: an
under-iterated frame-rate solver can stretch springs to fifty times their length while
the particles fall no faster than gravity lets them, and only the springs' energy shows
it (``tests/test_reliability.py``). S is summed inside the step's kernels (a batch of
substeps checks it at every substep, ``check``); P is the terms' energies, summed by
``Diagnostics.stored`` after every step from Python and after a batch's last substep
(a batch whose end fails is run again one substep at a time to find the first bad one).

An explicit integrator's blow-up turns energy from the springs into motion every half
period, so S crosses the limit within a step or two of the total energy doing so, while
the cloth still looks like cloth (``tests/test_reliability.py`` checks the kept state's
strain for each explicit integrator's blow-up).
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..features import FEATURES
from ..runtime import serial

NO_PARTICLE = 2147483647


@ti.data_oriented
class EnergyBudget:
    """The budget of one model: ``limits`` (f64 field: limit at t_b (J), gain (J/s),
    stretch (J/s^2), t_b (s)) and ``enabled`` (False where attraction has no softening,
    or as asked: ``Simulator(energy_bound=False)``). ``rebase`` recomputes it from an
    energy dict; ``check`` is the per-step test as a ``ti.func``."""

    def __init__(self, model, enabled=True):
        scene = model.scene
        self.model = model
        self.mass, self.params = model.mass, model.params
        self.enabled = enabled and None not in self._floors()
        springs = scene.springs
        pinned = np.asarray(scene.pinned, dtype=bool)
        self._pin_springs = pinned[springs["pairs"]].any(axis=1) if len(springs["pairs"]) \
            else np.zeros(0, dtype=bool)
        # float64 where the backend has it (runtime.accumulator), like the diagnostics
        self.acc = runtime.accumulator()
        self.limits = ti.field(self.acc, shape=4)
        self.wind_seen = 0.0
        self.values = {}

    def _inflow_speeds(self, velocities, colliders_off):
        """(u, u_up, u_pin, w): the fastest moving collider (of those switched on) or
        pinned particle, its fastest motion against gravity, the fastest pinned particle,
        the fastest wind."""
        scene, model = self.model.scene, self.model
        off = set(colliders_off)
        moving = [np.asarray(c["velocity"], float) for i, c in enumerate(scene.colliders)
                  if i not in off]
        pinned = np.asarray(scene.pinned, dtype=bool)
        pins = velocities[pinned] if pinned.any() else np.zeros((0, 3))
        g = np.asarray(scene.gravity, float)
        up = -g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.zeros(3)
        motions = np.concatenate([np.reshape(moving, (-1, 3)), pins])
        u = float(np.linalg.norm(motions, axis=1).max()) if len(motions) else 0.0
        u_up = float(max((motions @ up).max(), 0.0)) if len(motions) else 0.0
        u_pin = float(np.linalg.norm(pins, axis=1).max()) if len(pins) else 0.0
        w = 0.0
        wind = None if model.wind is None else model.wind.settings
        if wind is not None:
            w = (self.wind_seen if wind["callable"] is not None else
                 float(np.linalg.norm(wind["velocity"]) + np.linalg.norm(wind["amplitude"])))
        return u, u_up, u_pin, w

    def _floors(self):
        """Each feature's lowest potential energy (None: unbounded below) at the scene's
        current masses."""
        scene = self.model.scene
        return [f.floor(getattr(scene, f.name), scene) for f in FEATURES
                if getattr(scene, f.name) is not None]

    def rebase(self, energy, positions, velocities, t, colliders_off=()):
        """A new baseline at time t from ``energy`` (``Simulator.energy()``'s dict), the
        state's (N,3) positions and velocities and the colliders switched off."""
        scene = self.model.scene
        self.floor = sum(f for f in self._floors() if f is not None)
        s_b = energy["kinetic"] + energy["gravity"]
        p_b = energy["total"] - s_b
        g = float(np.linalg.norm(scene.gravity))
        size = float(np.linalg.norm(np.ptp(positions, axis=0)))
        m = float(scene.masses[~np.asarray(scene.pinned, dtype=bool)].sum())   # free mass
        u, u_up, u_pin, w = self._inflow_speeds(velocities, colliders_off)
        margin = energy["kinetic"] + max(p_b, 0.0) + m * g * size + 0.5 * m
        inflow = 2.0 * m * (u + w) ** 2
        k_pin = float(scene.springs["stiffness"][self._pin_springs].sum()) if u_pin else 0.0
        self.values = {"baseline": s_b + p_b, "margin": margin, "inflow": inflow,
                       "gain": m * g * u_up, "stretch": 0.5 * k_pin * u_pin ** 2,
                       "floor": self.floor, "time": float(t)}
        self.limits.from_numpy(np.array([s_b + p_b - self.floor + margin + inflow,
                                         m * g * u_up, 0.5 * k_pin * u_pin ** 2, t]).astype(
            np.float64 if self.limits.dtype == ti.f64 else np.float32))

    def see_wind(self, speed):
        """A callable gust reached ``speed`` (m/s): raise the inflow if it is the fastest
        so far. Returns True when the limits changed."""
        if speed <= self.wind_seen:
            return False
        self.wind_seen = float(speed)
        return True

    def limit(self, t):
        """The limit on S + P - P_min at time t (J), as ``check`` has it."""
        c = self.limits.to_numpy()
        tau = t - c[3]
        return float(c[0] + c[1] * tau + c[2] * tau * tau)

    @ti.func
    def check(self, x, v, t, x_bound, v_bound, stored):
        """-1 when the state (x, v) at time t is good; p when particle p (the smallest) is
        non-finite or beyond the bounds; n + p when the kinetic + gravitational energy
        plus ``stored`` (P - P_min, or 0 where P is checked later) exceeds the limit, p
        the particle with the most kinetic energy."""
        n = x.shape[0]
        acc = self.acc
        bad = NO_PARTICLE
        s = ti.cast(0.0, acc)
        fastest = ti.cast(0.0, acc)
        g = ti.Vector([self.params[0], self.params[1], self.params[2]])
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(n):
            ok = True
            for c in ti.static(range(3)):
                if not (abs(x[p][c]) <= x_bound and abs(v[p][c]) <= v_bound):
                    ok = False
            if not ok:
                ti.atomic_min(bad, p)
            kinetic = ti.cast(0.5 * self.mass[p] * v[p].dot(v[p]), acc)
            s += kinetic - ti.cast(self.mass[p] * g.dot(x[p]), acc)
            ti.atomic_max(fastest, kinetic)
        result = -1
        if bad != NO_PARTICLE:
            result = bad
        elif ti.static(self.enabled):
            tau = ti.cast(t, acc) - self.limits[3]
            if s + ti.cast(stored, acc) > self.limits[0] + tau * (
                    self.limits[1] + tau * self.limits[2]):
                result = n
                for p in range(n):
                    if ti.cast(0.5 * self.mass[p] * v[p].dot(v[p]), acc) == fastest \
                            and result == n:
                        result = n + p
        return result


@ti.kernel
def check_state(budget: ti.template(), x: ti.template(), v: ti.template(), t: float,
                x_bound: float, v_bound: float, stored: ti.f64) -> ti.i32:
    return budget.check(x, v, t, x_bound, v_bound, stored)
