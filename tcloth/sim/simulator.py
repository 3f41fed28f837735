"""Simulator: a Scene turned into a Model, two States and an integrator."""
from __future__ import annotations

from typing import Any, Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike

from . import checkpoint
from .batch import Batches
from .. import runtime
from .budget import EnergyBudget
from .constraints import StrainLimiter
from .current_mesh import CurrentMesh
from .diagnostics import Diagnostics
from ..errors import InstabilityError, SceneError
from ..features.wind import wind_velocity
from .instability import StepCheck
from .live import LiveParameters
from .split import StepSplitter, check_split
from .tearing import Tearing
from .welds import Welds
from ..contact import ContactStage
from ..contact.topology import cloth_primitives
from ..integrators import INTEGRATORS
from ..model.model import Model, copy_state
from ..runtime import serial_count
from ..scene.scene import Scene
from ..terms.grab import GrabSpring
from ..validate import as_index, as_points, as_scalar, as_vec3

def _integrator_class(name):
    if name not in INTEGRATORS:
        raise SceneError(f"integrator must be one of {sorted(INTEGRATORS)} (got {name!r})")
    return INTEGRATORS[name]


def _default_grab_stiffness(scene):
    return next((k for k in (scene.mean_stiffness("structural"), scene.mean_stiffness())
                 if k is not None), 100.0)


class Simulator(LiveParameters, CurrentMesh):
    """Advance a scene in time.

    Args:
        scene: a tcloth.Scene.
        integrator: a name in ``tcloth.integrators.INTEGRATORS``: "forward_euler",
            "symplectic_euler" (default), "verlet", "rk4" (explicit); "backward_euler",
            "projective" (implicit); "vbd", "xpbd" (real-time solvers).
        dt: time step, s, > 0.
        grid_stencil: the per-particle grid stencil for cloth springs (default), or the
            spring list (False): the same forces.
        position_bound: a step that leaves |x_k| <= position_bound (m, default 1e6)
            or |v_k| <= velocity_bound (m/s, default 1e8) in any coordinate
            raises InstabilityError, as does any non-finite value, and a step that leaves
            the scene with more energy (kinetic, gravitational and stored: springs,
            hinges, membrane, pressure, contacts) than it can supply (``budget.py``: the
            energy at the last baseline plus what wind, moving colliders and moving pins
            can add, plus a margin of the scene's energy scale).
        velocity_bound: see position_bound.
        strain_bound: a step that stretches a membrane triangle, or a spring that pulls
            harder than twice the scene's weight, beyond this strain (default 1.0: twice
            its rest length, beyond any woven or knitted fabric's breaking strain) fails
            the instability test (``instability.py`` says why the weight); None switches
            it off.
        energy_bound: apply that energy budget (default True); False leaves only the
            non-finite values and the two bounds (to study how an integrator's energy
            grows, as forward Euler's does on undamped springs).
        strain_limiting: apply the scene's strain limit (default True; see
            ``set_strain_limiting``).
        split: a step that fails the instability test is taken again from its start as
            2, 4, ... steps of dt / 2, dt / 4, ..., up to this many (default True: 64;
            False or 1: raise at once), and InstabilityError is raised only past that;
            ``step_stats()`` counts the splits (``split.py``).
        colliders_off: indices into ``scene.colliders`` of colliders switched off
            (see ``set_collider_enabled``).
        grab: build the grab spring (``grab``/``release``: the viewer's mouse drag);
            without it nothing of it is compiled or launched.
        batch: let ``step(n)`` run its n substeps in one kernel launch where the scene
            allows (default True; ``fusion()`` says whether it does, and why not). The
            results are the same numbers either way.
        compile_ahead: compile every kernel the contact stage may need in a later step
            while the simulator is built (True), so that no frame stalls compiling one
            mid-run, or each at its first use (False: a quicker start, for short runs
            such as tests); the numbers are the same. Default None: the environment's
            TCLOTH_COMPILE_AHEAD ("0" or "1"), else True.
        **options: the integrator's own options.

    Live changes (the viewer's controls, tcloth.grad) keep the state and recompile
    nothing, except a new integrator: ``set_integrator``, ``set_dt``, ``set_gravity``,
    ``set_air_drag``, ``set_air_damping``, ``set_springs``, ``set_wind``, ``set_feature``,
    ``set_collider``, ``set_collider_enabled``, ``set_strain_limiting``,
    ``grab``/``release``. Scene values they change are changed in ``scene`` too, and the
    switches are settings, so a checkpoint saved afterwards continues the changed run.

    Attributes:
        model: the scene's ``Model`` (static: what the kernels read of the scene).
        contact: the contact stage (``tcloth.contact.ContactStage``: self-collision's
            candidates, the mesh colliders' pairs and the guard of every step), or None in
            a scene with neither self-collision nor colliders. The simulator owns it and
            hands it to its integrator, which takes contact inside its step through it.
        integrator: the integrator, built for ``model`` and ``contact``.
    """

    def __init__(self, scene: Scene, integrator: str = "symplectic_euler", dt: float = 1e-3, *,
                 grid_stencil: bool = True, position_bound: float = 1e6,
                 velocity_bound: float = 1e8, strain_bound: Optional[float] = 1.0,
                 energy_bound: bool = True, strain_limiting: bool = True,
                 colliders_off: Sequence[int] = (), grab: bool = False, batch: bool = True,
                 split: bool = True, compile_ahead: Optional[bool] = None, **options: Any):
        if not isinstance(scene, Scene):
            raise SceneError(f"scene must be a tcloth.Scene (got {type(scene).__name__})")
        integrator_class = _integrator_class(integrator)
        self.dt = as_scalar("dt", dt, minimum=0.0, strict=True)
        self.position_bound = as_scalar("position_bound", position_bound, 0.0, strict=True)
        self.velocity_bound = as_scalar("velocity_bound", velocity_bound, 0.0, strict=True)
        self.strain_bound = (None if strain_bound is None else
                             as_scalar("strain_bound", strain_bound, 0.0, strict=True))
        self.integrator_name = integrator
        off = sorted({as_index("collider index", i, len(scene.colliders)) for i in colliders_off})
        self.settings = {"grid_stencil": bool(grid_stencil), "position_bound":
                         self.position_bound, "velocity_bound": self.velocity_bound,
                         "strain_bound": self.strain_bound, "energy_bound": bool(energy_bound),
                         "strain_limiting": bool(strain_limiting), "colliders_off": off,
                         "grab": bool(grab), "batch": bool(batch), "split": check_split(split),
                         "compile_ahead": runtime.compile_ahead(compile_ahead)}
        self.model = Model(scene, grid_stencil=bool(grid_stencil), colliders_off=off,
                           grab=GrabSpring() if grab else None)
        self.precision = runtime.precision()
        # the contact set and the guard, handed to the integrator for its step
        self.contact = (ContactStage(self.model, cloth_primitives(scene))
                        if self.model.self_collision is not None or self.model.colliders.count
                        else None)
        self.integrator = integrator_class(self.model, self.contact, **options)
        self._generation = self.model.generation
        self._states = [self.model.state(), self.model.state()]
        limit = self.model.strain_limit
        self._limiter = (StrainLimiter(self.model) if limit is not None and limit.count
                         else None)
        touching = scene.self_collision
        self._welds = Welds(self.model, 1e-3 if touching is None else touching["thickness"]) \
            if scene.welds else None
        self.diagnostics = Diagnostics(self.model, self.contact)
        self.budget = EnergyBudget(self.model, bool(energy_bound))
        self._checker = StepCheck(self)
        self._splitter = StepSplitter(self, self.settings["split"])
        self.num_steps = 0
        self._time_base, self._step_base = 0.0, 0      # the time at step _step_base
        self._batches = Batches(self)
        self._fusion = None          # (fusion(),) once computed; reset by the live changes
        self._tearing = Tearing(self.model) if self.model.tearing is not None else None
        if self.contact is not None:
            self.contact.refresh(self.state.x)
            if self.settings["compile_ahead"]:
                self._warm_contact()
        self._rebase()

    def _warm_contact(self):
        """The contact stage's kernels compiled now for the steps this simulator takes
        (a batch's, from the stage's start to the State; else from the State to the
        other), rather than in a later frame (``contact/warm.py``)."""
        a, b = self._states
        step = (self.contact.x_start, a.x, a.v) if self.fusion() is None else (a.x, b.x, b.v)
        self.contact.warm_up([step], a.x, a.t, self.dt)

    @property
    def scene(self) -> Scene:
        return self.model.scene

    @property
    def state(self):
        """The current State (Taichi fields)."""
        return self._states[0]

    @property
    def time(self) -> float:
        """Simulated time, s (dt may have changed along the way: ``set_dt``)."""
        return self._time_base + (self.num_steps - self._step_base) * self.dt

    def _check(self):
        runtime.check_generation(self._generation)

    def step(self, n: int = 1) -> None:
        """Advance n steps of dt. A step that fails the instability test is taken again
        as 2, 4, ... shorter steps (``split``, ``split.py``); past the finest split it
        raises InstabilityError, keeping the last good state. Where ``fusion()`` is None
        the n steps run in one kernel launch."""
        self._check()
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise SceneError(f"n must be an integer >= 0 (got {n!r})")
        limiter = self._limiter if self.settings["strain_limiting"] else None
        target = self.num_steps + int(n)
        while self.num_steps < target:
            if self._splitter.pieces == 1 and self.fusion() is None:
                try:
                    self._batches.run(target - self.num_steps, limiter)
                except InstabilityError as error:
                    self._splitter.recover(error, limiter)
            else:
                self._splitter.step(limiter)

    def _advance(self, limiter, t0=None, dt=None):
        """One step from the current state at time t0 (default: ``time``) of dt (default:
        ``dt``), checked: None (the states swapped, the clock left to the caller where t0
        is given), or the InstabilityError of a bad step (the state before it kept)."""
        whole = t0 is None
        t0, dt = (self.time, self.dt) if whole else (t0, dt)
        s_in, s_out = self._states
        self.model.colliders.advance(t0, dt)     # moving mesh colliders
        self.integrator.simulate(self.model, s_in, s_out, dt)
        if limiter is not None:
            limiter.apply(s_out, dt)
            self.integrator.invalidate()
        if self._welds is not None and self._welds.apply(s_out):
            self.integrator.invalidate()
        if self.contact is not None and self.contact.end_step(
                s_in.x, s_out.x, s_out.v, s_in.t, dt):
            self.integrator.invalidate()
            if self._welds is not None:        # a pair the guard's cuts took apart
                self._welds.apply(s_out)
        self._see_gust(t0 + dt)
        error = self._checker.verify(s_out, self.num_steps, t0 + dt, dt)
        if error is not None:
            return error
        # the end copied into the start's State rather than the two swapped, so that
        # every kernel that takes a State sees the same two and compiles once
        cached = self.integrator.holds_forces(s_out)
        copy_state(s_in, s_out)
        if cached:
            self.integrator.adopt_forces(s_in)
        if self._tearing is not None and self._tearing.after_step(s_in.x):
            self.integrator.parameters_changed()     # the springs' values changed
            self._rebase()
        if whole:
            self.num_steps += 1
            self.state.t = self.time
        else:
            self.state.t = t0 + dt
        return None

    def step_stats(self) -> dict:
        """dict of how the steps were split (``split.py``): split_steps (steps that took
        several pieces), pieces (how many they took), retries (failed attempts taken again
        finer), finest (the most pieces a step took), pieces_now (the split the next step
        starts with: 1 is the whole step)."""
        self._check()
        return self._splitter.stats()

    def fusion(self) -> Optional[str]:
        """None where ``step(n)`` runs its n substeps in one kernel launch (``batch.py``),
        else the reason why it launches kernels for every substep (one line)."""
        self._check()
        if self._fusion is None:
            self._fusion = (self._why_not_batched(),)
        if self._fusion[0] is None and self.contact is not None and self.contact.recording:
            return "a gradient's run keeps every step's contact guard from Python"
        return self._fusion[0]

    def _why_not_batched(self):
        if not self.settings["batch"]:
            return "batches are switched off (Simulator(..., batch=False))"
        if not runtime.cpu():
            return (f"on {runtime.arch_name()} the loops of a step run in parallel, which a "
                    "batch's one thread would not")
        if not self.integrator.batched:
            return (f"integrator '{self.integrator_name}' steps from Python (its solver "
                    "decides between launches)")
        if self._welds is not None:
            return "welded seams merge their pairs from Python after each step"
        n = self.model.particle_count
        if not serial_count(n):
            return f"the {n} particles' loops run on several threads"
        why = self.integrator.batch_obstacle() or (self.contact and
                                                   self.contact.batch_obstacle())
        if why is None and self._limiter is not None and self.settings["strain_limiting"]:
            why = self._limiter.batch_obstacle()
        return why or (self._tearing and self._tearing.batch_obstacle())

    def time_at(self, steps: int) -> float:
        """The time after ``steps`` steps in all (at the current dt since its last change)."""
        return self._time_base + (steps - self._step_base) * self.dt

    def _see_gust(self, t):
        """A callable gust's speed at t into the energy budget (its fastest so far)."""
        wind = self.model.wind
        if wind is not None and wind.settings["callable"] is not None:
            if self.budget.see_wind(float(np.linalg.norm(wind_velocity(wind.settings, t)))):
                self._rebase()

    def _rebase(self):
        """A new energy baseline at the current state (``budget.py``): after a change
        that adds or removes energy from outside the equations of motion."""
        state = self.state
        scene = self.scene
        free = float(scene.masses[~np.asarray(scene.pinned, dtype=bool)].sum())
        self.diagnostics.set_load(2.0 * free * float(np.linalg.norm(scene.gravity)))
        self.budget.rebase(self.diagnostics.energy(state), runtime.to_numpy(state.x),
                            runtime.to_numpy(state.v), self.time,
                            self.settings["colliders_off"])

    def positions(self) -> np.ndarray:
        """(N,3) NumPy copy of the positions, m."""
        self._check()
        return runtime.to_numpy(self.state.x)

    def velocities(self) -> np.ndarray:
        """(N,3) NumPy copy of the velocities, m/s."""
        self._check()
        return runtime.to_numpy(self.state.v)

    def forces(self) -> np.ndarray:
        """(N,3) total force on each particle at the current state, N."""
        self._check()
        self.integrator.forces_at(self.state)
        return runtime.to_numpy(self.state.f)

    def set_state(self, positions: Optional[ArrayLike] = None,
                  velocities: Optional[ArrayLike] = None) -> None:
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
        self._state_changed()
        self._rebase()

    def _state_changed(self):
        """The state was set from outside the step (``set_state``, a split step's start
        restored): the integrator's caches dropped, the contact list made to cover it."""
        self.integrator.invalidate()
        if self.contact is not None:
            self.contact.refresh(self.state.x)

    def reset(self, dt: Optional[float] = None) -> None:
        """Back to the scene's initial positions and velocities at t = 0, optionally with a
        new time step dt (s, > 0): the same compiled simulator runs again (studies over dt
        need no recompilation)."""
        self._check()
        if dt is not None:
            self.dt = as_scalar("dt", dt, minimum=0.0, strict=True)
        self.num_steps = 0
        self._time_base, self._step_base = 0.0, 0
        self.state.t = 0.0
        if self._welds is not None:
            self._welds.reset()
        if self.contact is not None:
            self.contact.reset_stats()          # a new run counts from zero
        self._splitter.reset()
        if self._tearing is not None:
            self._tearing.mend()
            self._parameters_changed()
        self.set_state(self.scene.positions, self.scene.velocities)

    # -- live changes ------------------------------------------------------------------------
    def set_integrator(self, integrator: str, **options: Any) -> None:
        """Continue with another integrator (and options) from the current state, on the
        same model (its kernels compile on first use)."""
        self._check()
        self.integrator = _integrator_class(integrator)(self.model, self.contact, **options)
        self.integrator_name = integrator
        self._batches.forget()
        self._fusion = None

    def set_integrator_options(self, **changes: Any) -> None:
        """Change the integrator's live options (``Integrator.set_options``: e.g. VBD's,
        XPBD's and projective's iterations) from the next step on, keeping its compiled
        kernels; the batches, which compile options in, compile again."""
        self._check()
        self.integrator.set_options(**changes)
        self._batches.forget()
        self._fusion = None

    def set_dt(self, dt: float) -> None:
        """Continue with time step dt (s, > 0); the time so far is kept."""
        self._check()
        dt = as_scalar("dt", dt, minimum=0.0, strict=True)
        self._time_base, self._step_base = self.time, self.num_steps
        self.dt = dt

    def set_strain_limiting(self, enabled: bool) -> None:
        """Apply the scene's strain limit after each step (True) or not."""
        self.settings["strain_limiting"] = bool(enabled)
        self._fusion = None

    def set_batching(self, enabled: bool) -> None:
        """Let ``step(n)`` run its substeps in one kernel launch where it can (True), or
        launch each step's kernels from Python (False: the contact stage then sees every
        step, as a gradient's runs need)."""
        self.settings["batch"] = bool(enabled)
        self._fusion = None

    def grab(self, particle: int, target: ArrayLike, stiffness: Optional[float] = None,
             damping: Optional[float] = None) -> None:
        """Pull particle ``particle`` towards ``target`` (3,) m with a zero-rest-length
        spring (``terms/grab.py``) until ``release``; the simulator must be made with
        grab=True. stiffness (N/m) defaults to the mean structural spring stiffness (the
        mean of all springs without structural ones, 100 N/m without springs); damping
        (N s/m) to critical for the particle, 2 sqrt(k m)."""
        self._check()
        if self.model.grab is None:
            raise SceneError("this simulator has no grab spring: make it with "
                             "Simulator(..., grab=True)")
        particle = as_index("particle", particle, self.model.particle_count)
        if self.scene.pinned[particle]:
            raise SceneError(f"particle {particle} is pinned and cannot be grabbed")
        target = as_vec3("target", target)
        k = _default_grab_stiffness(self.scene) if stiffness is None else \
            as_scalar("stiffness", stiffness, minimum=0.0)
        c = 2.0 * np.sqrt(k * self.scene.masses[particle]) if damping is None else \
            as_scalar("damping", damping, minimum=0.0)
        self.model.grab.hold(particle, target, k, c)
        self.integrator.invalidate()
        self._rebase()

    def release(self) -> None:
        """Let go of the grabbed particle (nothing happens when none is held)."""
        self._check()
        if self.model.grab is not None:
            self.model.grab.release()
            self.integrator.invalidate()
            self._rebase()

    @property
    def grabbed(self) -> Optional[dict]:
        """None, or dict(particle, target, stiffness, damping) of the grab spring."""
        self._check()
        return None if self.model.grab is None else self.model.grab.held()

    def save(self, path: str) -> None:
        """Write scene, settings and state to ``path`` (.npz), atomically."""
        self._check()
        checkpoint.save(self, path)

    @classmethod
    def load(cls, path: str) -> Simulator:
        """A Simulator continuing exactly where the saved one stopped (bit for bit on the
        CPU where the kernels are deterministic: grid stencils and scenes below
        SERIAL_BELOW particles). The current precision must match the checkpoint's."""
        return checkpoint.load(cls, path)

    def energy(self) -> dict:
        """dict of energies, J: kinetic, spring, gravity, contact, total."""
        self._check()
        return self.diagnostics.energy(self.state)

    def momentum(self) -> tuple:
        """(linear (3,), angular about the origin (3,))."""
        self._check()
        return self.diagnostics.momentum(self.state)

    def contact_stats(self) -> dict:
        """dict of the contact stage's statistics (``contact.stage.STATS`` says what each
        key counts; {} in a scene without self-collision or colliders) and the active
        self-contacts ("point_triangle", "edge_edge") and collider contacts ("collider":
        free particles within a collider's thickness)."""
        self._check()
        if self.contact is None:
            return {}
        return {**self.contact.contact_stats(), **self.self_contacts(),
                "collider": self.diagnostics.collider_contacts(self.state)}

    def self_contacts(self) -> dict:
        """{"point_triangle": n, "edge_edge": m}: the self-contacts closer than the
        thickness at the current state (both 0 without ``Scene.set_self_collision``)."""
        self._check()
        return self.diagnostics.self_contacts(self.state)

    def max_strain(self) -> float:
        """Max over springs of (length - rest) / rest (springs that broke left out)."""
        self._check()
        return self.diagnostics.max_strain(self.state)
