"""Reverse-mode gradients of a loss over a simulated trajectory (``Trajectory``).

The forward run is the simulator's own (``Simulator.step``), one step at a time, storing
the state every ``checkpoint_every`` steps. The backward run walks the checkpoints' segments
from the last: it runs the segment again from its checkpoint (the same steps, so the same
states), then takes the steps' adjoints in reverse order, carrying the adjoints (x_bar,
v_bar) of the positions and velocities and accumulating the parameters' gradients.

A step's adjoint is ``steps.StepAdjoints``'s (one per integrator; ``adjoint.StepAdjoint``
gives the vector-Jacobian products of its kernel).

Controls: ``controls`` (steps, pinned, 3) set the pinned particles' velocities before each
step (they move x += h u during step n); their gradient is the adjoint of those velocities.
"""
import time
import warnings
from typing import Any, Dict, Iterable, List, Optional, Tuple, Union

import numpy as np
import taichi as ti

from .. import runtime
from ..errors import GradientWarning, SceneError
from ..integrators.implicit import BackwardEuler
from ..scene.scene import KIND_CODE, Scene
from ..sim.simulator import Simulator
from ..validate import as_int
from .adjoint import StepAdjoint, unsupported
from .frozen import StepRecord, pull_back
from .losses import Loss
from .result import Result
from .projected import ProjectionAdjoint, before
from .sweep import SweepAdjoint, TruncationAdjoint
from .parameters import MEMBRANE, bending_gradient, masses_gradient, membrane_gradient
from .steps import StepAdjoints

INTEGRATORS = ("symplectic_euler", "backward_euler", "projective")


class Trajectory(StepAdjoints):
    """``steps`` steps of ``scene`` with ``integrator`` ("symplectic_euler",
    "backward_euler" or "projective") at ``dt``; ``options`` go to the integrator. Its
    parameters (``names``) are read with ``value(name)`` and changed with ``set(name,
    value)`` (nothing is compiled again); ``gradient(loss, wrt)`` runs the trajectory and
    returns the loss and its gradient.

    Parameters (names): "<kind>.stiffness" and "<kind>.damping" for each spring kind the
    scene has (one value for the kind: its springs' common k_s, k_d); "bending" (the hinge
    bending rigidities B of ``Scene.set_bending``, N m, (cloths, 2): (warp, weft) per cloth;
    a mesh cloth's hinges take its warp, and its weft must equal it);
    "membrane.stretch_warp", "membrane.stretch_weft" and "membrane.shear"
    (``Scene.set_membrane``'s C_u, C_v, G, N/m, one value each over its cloths); "gravity"
    (3,); "air_drag" (the scene's c); "masses" (each particle's, (n,), kg: a fabric's
    density is their scale; ``Scene.set_masses``: the air damping, the membrane's and the
    colliders' damping follow them, the springs' k_d stay); "wind" (its mean velocity
    (3,), m/s);
    "collider<i>.friction" and "collider<i>.stiffness" (scene collider i); "positions" and
    "velocities" (the initial state, (n, 3)); "controls" (the pinned particles' velocities,
    (steps, pinned, 3)).

    checkpoint_every: the states stored by the forward run (every k-th; default about
    sqrt(steps), which keeps 2 sqrt(steps) states and runs each step twice); an attribute,
    which may be changed between runs, as may the number of steps (``set_steps``).
    adjoint_tol: the relative residual of the implicit integrators' adjoint solves.
    forward_tol: projective dynamics' steps whose residual (``stats["residual"]``) the
    forward run left above this are listed (``Result.unconverged_steps``) and warned of:
    the adjoint is the converged step's, linearised where the iterations stopped, and
    far from convergence that is not a derivative of anything the run computed
    (docs/grad.md: 1.6e33 where central differences of the run give -7.7).
    """

    def __init__(self, scene: Scene, steps: int, dt: float, integrator: str = "symplectic_euler",
                 *, checkpoint_every: Optional[int] = None, adjoint_tol: float = 1e-10,
                 forward_tol: float = 1e-6, **options: Any):
        if integrator not in INTEGRATORS:
            raise SceneError(f"integrator must be one of {INTEGRATORS} for gradients (got "
                             f"{integrator!r})")
        self.controls = None
        self.set_steps(steps)
        if checkpoint_every is None:
            checkpoint_every = max(1, int(round(np.sqrt(self.steps))))
        self.checkpoint_every = as_int("checkpoint_every", checkpoint_every, 1)
        self.adjoint_tol, self.forward_tol = float(adjoint_tol), float(forward_tol)
        self.implicit = integrator in ("backward_euler", "projective")
        self.projective = integrator == "projective"
        self._forward_residual = 0.0
        self.guarded_steps, self.projected_steps = [], []     # the last forward run's
        self.unconverged_steps = []
        # during a gradient: the model's inverse masses in NumPy (symplectic Euler's
        # update and the guard's corrections read them) and their share of dL/dm
        self._inv_mass = self._mass_bar = None
        why = unsupported(scene)
        if why is not None:
            raise SceneError(f"tcloth.grad: {why}")
        if self.projective and options.setdefault("planes", False):
            raise SceneError("tcloth.grad: projective's planes have no adjoint (got planes=True)")
        self.sim = Simulator(scene, integrator=integrator, dt=dt, **options)
        self.scene = scene
        self.adjoint = StepAdjoint(self.sim.model, self.implicit, self.projective)
        self.adjoint.load()
        projection = next((term for term in getattr(self.sim.integrator, "projections", ())
                           if term.name == "self_contact"), None)
        self.record = StepRecord(self.sim.model, self.sim.contact, projection)
        self._projection = (ProjectionAdjoint(projection.table, projection.log.capacity)
                            if projection is not None else None)
        self._sweep = None          # the collider sweep's adjoint, built at its first cut
        self._truncation = None     # the fail-safe's, likewise
        self.pinned = np.flatnonzero(scene.pinned)
        self.free = np.flatnonzero(~scene.pinned)
        self.initial = {"positions": scene.positions.astype(np.float64),
                        "velocities": scene.velocities.astype(np.float64)}
        kinds = scene.springs["kind"][self.sim.model.spring_order]
        self._kind_rows = {name: kinds == code for name, code in KIND_CODE.items()
                           if (kinds == code).any()}
        if self.projective:
            # projective's adjoint solves are preconditioned by backward Euler's Hessian
            self._newton = BackwardEuler(self.sim.model, self.sim.contact, exact_hessian=False)
        if self.implicit:
            self._x_start, self._rhs = (ti.Vector.field(3, runtime.real(),
                                                        shape=scene.num_particles)
                                        for _ in range(2))

    def set_steps(self, steps: int) -> None:
        """Run ``steps`` steps from now on (the controls, where set, must have as many)."""
        steps = as_int("steps", steps, 1)
        if self.controls is not None and len(self.controls) != steps:
            raise SceneError(f"the controls hold {len(self.controls)} steps, not {steps}: "
                             "set('controls', ...) to new ones or None first")
        self.steps = steps

    # -- parameters ---------------------------------------------------------------------------
    @property
    def names(self) -> List[str]:
        """The parameters' names (see the class)."""
        names = [f"{kind}.{what}" for kind in self._kind_rows
                 for what in ("stiffness", "damping")]
        if self.sim.model.bending is not None:
            names += ["bending"]
        if self.sim.model.membrane is not None:
            names += [f"membrane.{what}" for what in MEMBRANE]
        names += ["masses", "gravity", "air_drag"]
        if self.sim.model.wind is not None:
            names += ["wind"]
        names += [f"collider{i}.{what}" for i in range(len(self.scene.colliders))
                  for what in ("friction", "stiffness")]
        return names + ["positions", "velocities", "controls"]

    def _check_name(self, name):
        if name not in self.names:
            raise SceneError(f"no parameter {name!r} (this trajectory's: {self.names})")

    def value(self, name: str) -> Union[float, np.ndarray]:
        """The parameter's current value (a float or a NumPy array)."""
        self._check_name(name)
        scene = self.scene
        if name in self.initial:
            return self.initial[name].copy()
        if name == "controls":
            return None if self.controls is None else self.controls.copy()
        if name == "gravity":
            return np.array(scene.gravity, dtype=np.float64)
        if name == "air_drag":
            return float(scene.air_drag)
        if name == "masses":
            return scene.masses
        if name == "bending":
            return np.array(scene.bending["rigidity"], dtype=np.float64)
        if name == "wind":
            return np.array(scene.wind["velocity"], dtype=np.float64)
        head, what = name.split(".")
        if head.startswith("collider"):
            return float(scene.colliders[int(head[len("collider"):])][what])
        if head == "membrane":
            key, column = MEMBRANE[what]
            values = np.asarray(scene.membrane[key])
            return self._one(name, values if column is None else values[:, column])
        return self._one(name, scene.springs[what][scene.springs["kind"] == KIND_CODE[head]])

    @staticmethod
    def _one(name, values):
        """The one value of ``values`` (a parameter shared by springs or cloths)."""
        if np.ptp(values) > 0.0:
            raise SceneError(f"{name} is not one value in the scene (it ranges over "
                             f"{values.min():.6g} .. {values.max():.6g}): it needs one")
        return float(values[0])

    def central_difference(self, loss: Loss, name: str, direction: Union[float, np.ndarray],
                           step: float) -> float:
        """The loss's central difference along ``direction`` of parameter ``name`` (a
        step of ``step``; two forward runs), the parameter set back after: the check of
        a gradient's component or directional derivative."""
        value = self.value(name)
        ends = []
        for sign in (1.0, -1.0):
            self.set(name, value + sign * step * direction)
            ends.append(self.forward(loss)[0])
        self.set(name, value)
        return (ends[0] - ends[1]) / (2.0 * step)

    def set(self, name: str, value: Union[float, np.ndarray]) -> None:
        """Change a parameter (see the class) for the next ``gradient``."""
        self._check_name(name)
        n = self.scene.num_particles
        if name in self.initial:
            value = np.asarray(value, dtype=np.float64)
            if value.shape != (n, 3) or not np.all(np.isfinite(value)):
                raise SceneError(f"{name} must be finite with shape ({n}, 3) (got shape "
                                 f"{value.shape})")
            self.initial[name] = value.copy()
            return
        if name == "controls":
            shape = (self.steps, len(self.pinned), 3)
            value = None if value is None else np.asarray(value, dtype=np.float64)
            if value is not None and (value.shape != shape or not np.all(np.isfinite(value))):
                raise SceneError(f"controls must be finite with shape {shape} (got shape "
                                 f"{value.shape})")
            self.controls = None if value is None else value.copy()
            return
        sim = self.sim
        if name == "gravity":
            sim.set_gravity(value)
        elif name == "air_drag":
            sim.set_air_drag(value)
        elif name == "masses":
            sim.set_masses(value)
        elif name == "wind":
            sim.set_wind(value)
        elif name == "bending":
            sim.set_feature("bending", rigidity=value)
        else:
            head, what = name.split(".")
            if head.startswith("collider"):
                sim.set_collider(int(head[len("collider"):]), **{what: value})
            elif head == "membrane":
                key, column = MEMBRANE[what]
                values = np.array(self.scene.membrane[key], dtype=np.float64)
                values[..., slice(None) if column is None else column] = value
                sim.set_feature("membrane", **{key: values})
            else:
                sim.set_springs(head, **{what: value})
        self.adjoint.load(sim.settings["colliders_off"])

    # -- the runs -----------------------------------------------------------------------------
    def _apply_control(self, n):
        """The pinned particles' velocities of step n (before it), where controls are set."""
        if self.controls is None or not len(self.pinned):
            return
        v = self.sim.velocities()
        v[self.pinned] = self.controls[n]
        self.sim.set_state(velocities=v)

    def _state(self):
        return self.sim.positions().astype(np.float64), self.sim.velocities().astype(np.float64)

    def _run(self, start, stop, state, keep=False):
        """Steps start .. stop - 1 from ``state`` (the state at ``start``, before its
        control): the states start .. stop, each after its control where it has one;
        ``record`` holds what the steps read and what their guard did (kept where
        ``keep``)."""
        sim = self.sim
        sim.num_steps = start           # the time of step ``start`` (a gust reads it): the
        sim.state.t = sim.time          # simulator's clock counts from 0 at its reset
        sim.set_state(*state)
        states = []
        self.record.start(keep)
        batching = sim.settings["batch"]
        sim.set_batching(False)         # the contact stage sees every step's sweep
        try:
            for n in range(start, stop):
                self._apply_control(n)
                states.append(self._state())
                self.record.before(n)
                sim.step(1)
                self.record.after(n)
                if self.projective:
                    residual = sim.integrator.stats["residual"]
                    self._forward_residual = max(self._forward_residual, residual)
                    if not keep and residual > self.forward_tol:
                        self.unconverged_steps.append(n)
        finally:                        # (a step that raises leaves it as it was)
            sim.set_batching(batching)
        states.append(self._state())
        return states

    def forward(self, loss: Loss) -> Tuple[float, Dict[int, Tuple[np.ndarray, np.ndarray]]]:
        """The forward run alone: (loss value, the checkpoints {step: (x, v)}); the steps
        the guard changed in ``guarded_steps`` and ``projected_steps`` (``Result``)."""
        k, steps = self.checkpoint_every, self.steps
        self._forward_residual = 0.0
        self.guarded_steps, self.projected_steps, self.unconverged_steps = [], [], []
        state = self.initial["positions"], self.initial["velocities"]
        checkpoints, value = {0: state}, 0.0
        reads = set(loss.steps)
        for start in range(0, steps, k):
            stop = min(start + k, steps)
            states = self._run(start, stop, state)
            self.guarded_steps += sorted(self.record.guarded)
            self.projected_steps += sorted(self.record.projected)
            if start == 0:
                checkpoints[0] = states[0]      # as the simulator holds it, after control 0
            for m in range(start, stop + 1):
                if m in reads and (m > start or m == 0):
                    value += float(loss.evaluate(m, *states[m - start])[0])
            state = states[-1]
            checkpoints[stop] = state
        return value, checkpoints

    def gradient(self, loss: Loss, wrt: Optional[Iterable[str]] = None) -> Result:
        """The loss (``tcloth.grad.Loss``) over the trajectory and its gradient with
        respect to the parameters ``wrt`` (names; default all). Returns a ``Result``."""
        wrt = list(self.names) if wrt is None else list(wrt)
        for name in wrt:
            self._check_name(name)
        for m in loss.steps:
            if not 0 <= m <= self.steps:
                raise SceneError(f"the loss reads step {m}, outside 0 .. {self.steps}")
        t0 = time.perf_counter()
        value, checkpoints = self.forward(loss)
        t1 = time.perf_counter()
        self._warn()
        n, h, adj = self.scene.num_particles, self.sim.dt, self.adjoint
        adj.zero_parameter_grads()
        self._inv_mass = self.sim.model.inv_mass.to_numpy().astype(np.float64)
        self._mass_bar = np.zeros(n) if "masses" in wrt else None
        x_bar, v_bar = np.zeros((n, 3)), np.zeros((n, 3))
        controls_bar = np.zeros((self.steps, len(self.pinned), 3))
        reads = set(loss.steps)
        iterations, worst = 0, 0.0
        k = self.checkpoint_every
        starts = list(range(0, self.steps, k))
        segment = rows = 0
        for start in reversed(starts):
            stop = min(start + k, self.steps)
            states = self._run(start, stop, checkpoints[start], keep=True)
            segment = max(segment, len(states))
            rows = max(rows, self.record.nbytes)
            for m in range(stop - 1, start - 1, -1):
                if m + 1 in reads:
                    _, dx, dv = loss.evaluate(m + 1, *states[m + 1 - start])
                    x_bar += dx
                    if dv is not None:
                        v_bar += dv
                (x, v), (x1, _) = states[m - start], states[m + 1 - start]
                if m in self.record.rows:
                    adj.set_contacts(self.record.rows[m])
                planes = start_bar = None
                if m in self.record.projections:    # the guard's, then the solver's step
                    x1, x_bar, v_bar, planes, start_bar = self._guard_back(
                        self.record.projections[m], x, x_bar, v_bar)
                if m in self.record.corrections:    # projective's self-contact projection
                    x1, x_bar, v_bar = self._projection_back(self.record.corrections[m], x1,
                                                             x_bar, v_bar)
                if self.implicit:
                    adjoint = (self._projective_adjoint if self.projective
                               else self._implicit_adjoint)
                    x_bar, v_bar, iters, residual = adjoint(x, v, x1, x_bar, v_bar, h, m)
                    iterations += iters
                    worst = max(worst, residual)
                else:
                    x_bar, v_bar = self._explicit_adjoint(x, v, x_bar, v_bar, h, m)
                if planes is not None:      # the guard's planes, from the step's start
                    x_bar = x_bar + adj.plane_vjp(x, planes)
                if start_bar is not None:   # the guard's cuts, from the step's start
                    x_bar = x_bar + start_bar
                if self.controls is not None and len(self.pinned):
                    controls_bar[m] = v_bar[self.pinned]
                    v_bar[self.pinned] = 0.0
        if 0 in reads:
            _, dx, dv = loss.evaluate(0, *checkpoints[0])
            x_bar += dx
            if dv is not None:
                v_bar += dv
        t2 = time.perf_counter()
        grads = self._reduce(wrt, x_bar, v_bar, controls_bar)
        state_bytes = 2 * n * 3 * np.dtype(runtime.numpy_real()).itemsize
        return Result(value, grads, forward_seconds=t1 - t0, backward_seconds=t2 - t1,
                      memory_bytes=(len(checkpoints) + segment) * state_bytes + rows,
                      adjoint_iterations=iterations, adjoint_residual=worst,
                      forward_residual=self._forward_residual,
                      guarded_steps=list(self.guarded_steps),
                      unconverged_steps=list(self.unconverged_steps),
                      projected_steps=list(self.projected_steps))

    def _warn(self):
        """The forward run's steps whose derivative the gradient does not take."""
        if self.guarded_steps:
            warnings.warn(
                f"the contact stage's guard changed {len(self.guarded_steps)} of the "
                f"{self.steps} steps (the first: step {self.guarded_steps[0]}), or projective"
                " dynamics' projection made more corrections than its log keeps: the gradient"
                " takes the solver's step there (Result.guarded_steps)", GradientWarning,
                stacklevel=3)
        if self.unconverged_steps:
            warnings.warn(
                f"projective dynamics left {len(self.unconverged_steps)} of the {self.steps}"
                f" steps above forward_tol {self.forward_tol:g} (the first: step "
                f"{self.unconverged_steps[0]}; the largest residual "
                f"{self._forward_residual:.3g}): the gradient is the converged steps' "
                "linearised where the iterations stopped, not the run's; more iterations, "
                "a smaller dt (the iterations stall on a step that is not convex: "
                "Projective.step_residual's Jacobian shows it) or backward Euler "
                "(Result.unconverged_steps)", GradientWarning,
                stacklevel=3)

    def _guard_back(self, changes, x, x_bar, v_bar):
        """The adjoints of the solver's end of a step from those of the guard's, through
        the guard's changes as ``StepRecord`` kept them (the projection's corrections,
        the colliders' first sweep's cuts, the fail-safe's cuts, the solver's x1 and
        v1), the last first; the masses' share added to ``_mass_bar``. Returns (the
        solver's x1, x_bar, v_bar, the planes' adjoints for ``plane_vjp`` or None, the
        step start's share of the cuts or None)."""
        corrections, cuts, truncation, x1, v1 = changes
        planes = start_bar = None
        if truncation is not None:
            if self._truncation is None:
                self._truncation = TruncationAdjoint(self.sim.model.self_collision,
                                                     self.scene.num_particles)
            x_bar, v_bar, start_bar = self._truncation.vjp(truncation, x, x_bar, v_bar)
        if corrections is not None:
            x_bar, v_bar, inv_bar, planes = pull_back(corrections, self._inv_mass, x_bar,
                                                      v_bar)
            if self._mass_bar is not None:
                self._mass_bar -= self._inv_mass ** 2 * inv_bar
        if cuts is not None:
            if self._sweep is None:
                self._sweep = SweepAdjoint(self.adjoint.table, self.scene.num_particles)
            x_bar, v_bar, start = self._sweep.vjp(cuts, x, x1, v1, x_bar, v_bar)
            start_bar = start if start_bar is None else start_bar + start
        return x1, x_bar, v_bar, planes, start_bar

    def _projection_back(self, entries, x1, x_bar, v_bar):
        """The solver's x1 before projective's self-contact projection, and the adjoints of
        its end before it from those after (``projected.py``); the masses' to _mass_bar."""
        start = before(entries, x1)
        x_bar, v_bar, inv_bar = self._projection.pull_back(entries, self._inv_mass, start, x_bar,
                                                           v_bar)
        if self._mass_bar is not None:
            self._mass_bar -= self._inv_mass ** 2 * inv_bar
        return start, x_bar, v_bar

    def _reduce(self, wrt, x_bar, v_bar, controls_bar):
        adj, grads = self.adjoint, {}
        count = self.sim.model.spring_count
        for name in wrt:
            if name == "positions":
                grads[name] = x_bar.copy()
            elif name == "velocities":
                grads[name] = v_bar.copy()
            elif name == "controls":
                grads[name] = controls_bar.copy()
            elif name == "gravity":
                grads[name] = adj.params.grad.to_numpy()[:3].astype(np.float64)
            elif name == "air_drag":
                grads[name] = float(adj.drag.grad.to_numpy().sum())
            elif name == "masses":
                grads[name] = masses_gradient(self.sim.model, adj, self._inv_mass,
                                              self._mass_bar)
            elif name == "wind":
                grads[name] = adj.wind_params.grad.to_numpy()[:3].astype(np.float64)
            elif name == "bending":
                grads[name] = bending_gradient(self.sim.model, adj)
            else:
                head, what = name.split(".")
                if head == "membrane":
                    grads[name] = membrane_gradient(self.sim.model, adj, what)
                elif head.startswith("collider"):
                    row = self.sim.model.colliders.rows.index(int(head[len("collider"):]))
                    grads[name] = float(getattr(adj.table.data.grad, what).to_numpy()[row])
                else:
                    field = adj.ks if what == "stiffness" else adj.kd
                    rows = self._kind_rows[head]
                    grads[name] = float(field.grad.to_numpy()[:count][rows].sum())
        return grads
