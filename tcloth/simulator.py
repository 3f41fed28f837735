"""Simulator: a Scene turned into a Model, two States and an integrator."""
import numpy as np
import taichi as ti

from . import checkpoint, runtime
from .constraints import StrainLimiter
from .diagnostics import Diagnostics
from .errors import InstabilityError, SceneError
from .integrators import INTEGRATORS
from .model import Model
from .runtime import serial
from .scene import Scene
from .validate import as_points, as_scalar

_HINTS = {
    "forward_euler": "forward Euler gains energy at every dt on undamped springs: use "
                     "symplectic_euler, verlet or an implicit integrator",
}
_DEFAULT_HINT = ("try a smaller dt, more spring damping (k_d) or air drag, "
                 "or an implicit integrator")


@ti.kernel
def _first_bad_particle(x: ti.template(), v: ti.template(), x_bound: float,
                        v_bound: float) -> ti.i32:
    """Smallest id whose position or velocity is non-finite or out of bounds, else -1."""
    bad = 2147483647
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        ok = True
        for c in ti.static(range(3)):
            if not (abs(x[p][c]) <= x_bound and abs(v[p][c]) <= v_bound):
                ok = False
        if not ok:
            ti.atomic_min(bad, p)
    return -1 if bad == 2147483647 else bad


class Simulator:
    """Advance a scene in time.

    Args:
        scene: a tcloth.Scene.
        integrator: "forward_euler" | "symplectic_euler" | "verlet" | "rk4".
        dt: time step, s, > 0.
        grid_stencil: evaluate cloth springs with the per-particle grid stencil (default)
            rather than the spring list; both give the same forces.
        position_bound, velocity_bound: a step that leaves |x_k| <= position_bound (m,
            default 1e6) or |v_k| <= velocity_bound (m/s, default 1e8) in any coordinate
            raises InstabilityError, as does any non-finite value.
        **options: the integrator's own options.
    """

    def __init__(self, scene, integrator="symplectic_euler", dt=1e-3, grid_stencil=True,
                 position_bound=1e6, velocity_bound=1e8, **options):
        if not isinstance(scene, Scene):
            raise SceneError(f"scene must be a tcloth.Scene (got {type(scene).__name__})")
        if integrator not in INTEGRATORS:
            raise SceneError(f"integrator must be one of {sorted(INTEGRATORS)} "
                             f"(got {integrator!r})")
        self.dt = as_scalar("dt", dt, minimum=0.0, strict=True)
        self.position_bound = as_scalar("position_bound", position_bound, 0.0, strict=True)
        self.velocity_bound = as_scalar("velocity_bound", velocity_bound, 0.0, strict=True)
        self.integrator_name = integrator
        self.settings = {"grid_stencil": bool(grid_stencil),
                         "position_bound": self.position_bound,
                         "velocity_bound": self.velocity_bound}
        self.model = Model(scene, grid_stencil=bool(grid_stencil))
        self.precision = runtime.precision()
        self.integrator = INTEGRATORS[integrator](self.model, **options)
        self._generation = self.model.generation
        self._states = [self.model.state(), self.model.state()]
        limit = self.model.strain_limit
        self._limiter = (StrainLimiter(self.model) if limit is not None and self.model.limit_count
                         else None)
        self._diag = Diagnostics(self.model)
        self.num_steps = 0

    @property
    def scene(self):
        return self.model.scene

    @property
    def state(self):
        """The current State (Taichi fields)."""
        return self._states[0]

    @property
    def time(self):
        """Simulated time, s."""
        return self.num_steps * self.dt

    def _check(self):
        runtime.check_generation(self._generation)

    def step(self, n=1):
        """Advance n steps of dt. Raises InstabilityError on a bad step, keeping the last
        good state."""
        self._check()
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise SceneError(f"n must be an integer >= 0 (got {n!r})")
        for _ in range(int(n)):
            s_in, s_out = self._states
            self.integrator.simulate(self.model, s_in, s_out, self.dt)
            if self._limiter is not None:
                self._limiter.apply(s_out, self.dt)
                self.integrator.invalidate()
            bad = _first_bad_particle(s_out.x, s_out.v, self.position_bound,
                                      self.velocity_bound)
            if bad >= 0:
                self._raise_instability(bad)
            self._states.reverse()
            self.num_steps += 1
            self.state.t = self.time

    def _raise_instability(self, particle):
        step = self.num_steps + 1
        t = step * self.dt
        hint = _HINTS.get(self.integrator_name, _DEFAULT_HINT)
        raise InstabilityError(
            f"step {step} (t = {t:.6g} s, dt = {self.dt:.3g} s) of integrator "
            f"'{self.integrator_name}' left particle {particle} non-finite or beyond "
            f"|x| <= {self.position_bound:g} m, |v| <= {self.velocity_bound:g} m/s; "
            f"the last good state (t = {self.time:.6g} s) is kept. Hint: {hint}.",
            step=step, time=t, integrator=self.integrator_name)

    def positions(self):
        """(N,3) NumPy copy of the positions, m."""
        self._check()
        return self.state.x.to_numpy()

    def velocities(self):
        """(N,3) NumPy copy of the velocities, m/s."""
        self._check()
        return self.state.v.to_numpy()

    def forces(self):
        """(N,3) total force on each particle at the current state, N."""
        self._check()
        self.integrator.forces_at(self.state)
        return self.state.f.to_numpy()

    def set_state(self, positions=None, velocities=None):
        """Overwrite positions and/or velocities ((N,3) each)."""
        self._check()
        n = self.model.particle_count
        npr = runtime.numpy_real()
        for name, value, field in (("positions", positions, self.state.x),
                                   ("velocities", velocities, self.state.v)):
            if value is None:
                continue
            arr = as_points(name, value)
            if arr.shape != (n, 3):
                raise SceneError(f"{name} must have shape ({n}, 3) (got {arr.shape})")
            field.from_numpy(arr.astype(npr))
        self.integrator.invalidate()

    def reset(self, dt=None):
        """Back to the scene's initial positions and velocities at t = 0, optionally with a
        new time step dt (s, > 0): the same compiled simulator runs again (studies over dt
        need no recompilation)."""
        self._check()
        if dt is not None:
            self.dt = as_scalar("dt", dt, minimum=0.0, strict=True)
        self.set_state(self.scene.positions, self.scene.velocities)
        self.num_steps = 0
        self.state.t = 0.0

    def save(self, path):
        """Write scene, settings and state to ``path`` (.npz), atomically."""
        self._check()
        checkpoint.save(self, path)

    @classmethod
    def load(cls, path):
        """A Simulator continuing exactly where the saved one stopped (bit for bit on the
        CPU where the kernels are deterministic: grid stencils and scenes below
        SERIAL_BELOW particles). The current precision must match the checkpoint's."""
        meta, scene_arrays, files = checkpoint.read(path)
        runtime.ensure_init()
        if meta["precision"] != runtime.precision():
            raise SceneError(f"checkpoint {path!r} was saved in precision "
                             f"{meta['precision']!r}; call tcloth.init(precision="
                             f"{meta['precision']!r}) before loading it")
        scene = checkpoint.scene_from_arrays(meta["scene"], scene_arrays)
        sim = cls(scene, meta["integrator"], dt=meta["dt"], **meta["settings"],
                  **meta["options"])
        npr = runtime.numpy_real()
        state = sim.state
        state.x.from_numpy(files["state_x"].astype(npr))
        state.v.from_numpy(files["state_v"].astype(npr))
        state.f.from_numpy(files["state_f"].astype(npr))
        if meta["forces_valid"]:
            sim.integrator.adopt_forces(state)
        sim.num_steps = int(meta["num_steps"])
        state.t = sim.time
        return sim

    def energy(self):
        """dict of energies, J: kinetic, spring, gravity, contact, total."""
        self._check()
        return self._diag.energy(self.state)

    def momentum(self):
        """(linear (3,), angular about the origin (3,))."""
        self._check()
        return self._diag.momentum(self.state)

    def self_contacts(self):
        """{"point_triangle": n, "edge_edge": m}: the self-contacts closer than the
        thickness at the current state (both 0 without ``Scene.set_self_collision``)."""
        self._check()
        return self._diag.self_contacts(self.state)

    def max_strain(self):
        """Max over springs of (length - rest) / rest."""
        self._check()
        return self._diag.max_strain(self.state)
