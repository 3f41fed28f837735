"""Integrator base class: option parsing and the force workspace; the real-time solvers'
substep count."""
import math
from types import MappingProxyType

import taichi as ti

from ..scene import stability
from ..errors import SceneError
from ..terms.forces import Forces


def check_substeps(name, substeps, scene):
    """Check the option ``substeps`` of integrator ``name`` (an int >= 1 or "auto") and
    return the scene's explicit stability limit for "auto" (else None)."""
    if substeps == "auto":
        return stability.gershgorin_dt(scene)
    if not (isinstance(substeps, int) and not isinstance(substeps, bool) and substeps >= 1):
        raise SceneError(f"{name}'s substeps must be an int >= 1 or 'auto' (got {substeps!r})")
    return None


def substep_count(substeps, dt, iterations, explicit_limit):
    """The substeps of a step of dt: ``substeps``, or for "auto" (``explicit_limit`` set)
    ceil(dt / (iterations x explicit_limit)). A Gauss-Seidel sweep (VBD's, XPBD's) carries
    a change one particle further; in a step of h a stress wave crosses about h omega / 2
    particles (omega the highest frequency, 2 / omega the explicit integrators' stability
    limit). The iterations keep up with the wave, and a cloth that lands on a collider is
    stopped as a whole rather than torn, when h <= iterations x the explicit limit."""
    if explicit_limit is None:
        return substeps
    return max(1, math.ceil(dt / (iterations * explicit_limit) - 1e-9))


@ti.func
def substeps_in_kernel(substeps: ti.template(), dt, iterations: ti.template(),
                       explicit_limit: ti.template()):
    """``substep_count`` inside a kernel (a batch's ``advance``), in float64 as there;
    ``explicit_limit`` 0 where ``substeps`` is a number."""
    count = 1
    if ti.static(explicit_limit > 0.0):
        count = ti.max(1, ti.cast(ti.ceil(dt / (iterations * explicit_limit) - 1e-9), ti.i32))
    else:
        count = substeps
    return count


class Integrator:
    """One entry point: ``simulate(model, state_in, state_out, dt)``, which also sets
    ``state_out.t = state_in.t + dt``. An integrator keeps its workspace (forces, solver
    buffers), built from the model it is made for; it holds no simulation state, except a
    cache of forces where it says so (``Verlet``). ``contact`` is the simulator's contact
    stage (``Simulator.contact``: ``contact.ContactStage``, or None in a scene with
    neither self-collision nor colliders), the one object through which a solver takes
    contact inside its step: its searches, separating planes and hold.

    Subclasses list their options in ``defaults`` (name -> default); an unknown option
    raises SceneError naming it. ``options`` is read-only: ``set_options`` changes the
    ``live_options`` (those read from Python at every step, or re-derived by ``_configure``)
    in place and refuses the others, which shape what the integrator built (a new
    integrator takes them: ``Simulator.set_integrator``). Every integrator has ``forces``
    (its ``Forces``) and ``inv_mass`` (the model's field, read by its kernels).
    """
    name = "integrator"
    defaults = {}
    # True: a batch of steps (``Simulator.step(n)``) runs one step a launch, each checked
    # whole (the energy stored in springs included) from Python: for integrators whose
    # step costs many force passes, where a launch is cheap beside it
    checked_steps = False
    # True: the integrator gives ``advance(a, b, t, dt, fresh)``, its step as a ``ti.func``
    # that a batch of substeps (``batch.py``) runs in one launch where ``batch_obstacle()``
    # is None
    batched = False
    live_options = frozenset()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.batched != callable(getattr(cls, "advance", None)):
            raise TypeError(f"{cls.__name__}: batched = {cls.batched} but it "
                            f"{'lacks' if cls.batched else 'defines'} advance")

    def __init__(self, model, contact=None, **options):
        unknown = sorted(set(options) - set(self.defaults))
        if unknown:
            raise SceneError(f"unknown option {unknown[0]!r} for integrator {self.name!r} "
                             f"(its options: {sorted(self.defaults) or 'none'})")
        self._options = {**self.defaults, **options}
        self.options = MappingProxyType(self._options)
        self.contact = contact
        self.forces = Forces(model, contact=contact)
        self.inv_mass = model.inv_mass

    def set_options(self, **changes):
        """Change live options (``live_options``) from the next step on; an option that
        shapes what the integrator built raises SceneError saying how to change it. A
        simulator's ``set_integrator_options`` calls this and recompiles its batches (which
        compile options in)."""
        unknown = sorted(set(changes) - set(self.defaults))
        if unknown:
            raise SceneError(f"unknown option {unknown[0]!r} for integrator {self.name!r} "
                             f"(its options: {sorted(self.defaults) or 'none'})")
        fixed = sorted(set(changes) - self.live_options)
        if fixed:
            raise SceneError(f"{self.name}'s option {fixed[0]!r} shapes what the integrator "
                             f"built: give it to Simulator.set_integrator({self.name!r}, "
                             f"{fixed[0]}=...) (live options: {sorted(self.live_options)})")
        before = dict(self._options)
        self._options.update(changes)
        try:
            self._configure()
        except SceneError:
            self._options.update(before)
            raise

    def _configure(self):
        """Check the options and derive what depends on the live ones (at construction
        and after ``set_options``)."""

    def forces_at(self, state):
        """Make ``state.f`` hold the forces at (state.x, state.v) and time state.t."""
        self.forces.compute(state.x, state.v, state.t, state.f)

    def invalidate(self):
        """The simulator changed a state outside ``simulate`` (strain limiting, set_state):
        forget anything cached about it."""

    def parameters_changed(self):
        """The model's values changed (``Model.refresh``): forget anything built from
        them."""
        self.invalidate()

    def holds_forces(self, state):
        """True when ``state.f`` holds forces this integrator will reuse (checkpoints)."""
        return False

    def adopt_forces(self, state):
        """``state.f`` holds the forces a saved simulator had cached (checkpoints)."""

    def batch_obstacle(self):
        """None when ``advance`` may run in a batch of substeps, else why not (one line)."""
        return self.forces.batch_obstacle()

    def simulate(self, model, state_in, state_out, dt):
        raise NotImplementedError


class ForceCache:
    """For an integrator that leaves in ``state_out.f`` something its next step reuses
    (Verlet: the forces at the step's end; VBD: the step's net force): ``_cached`` is the
    State whose f holds it, forgotten when the state is changed from outside and kept by
    checkpoints. Put before ``Integrator`` in the bases."""
    _cached = None

    def invalidate(self):
        self._cached = None

    def holds_forces(self, state):
        return self._cached is state

    def adopt_forces(self, state):
        self._cached = state
