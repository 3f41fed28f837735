"""The instability test after every step of a ``Simulator``: the state's particles, its
energy with the part stored in springs, hinges, the membrane, pressure and contacts (the
budget: ``budget.py``), and the strain bound; and the InstabilityError a bad step raises,
with a hint at what to change. A failing step is split before anything is raised
(``split.py``).

The strain bound stands for a torn cloth: a spring stretched past ``strain_bound`` (default
1, twice its rest length) while it pulls harder than twice the weight of the scene's free
particles, 2 M |g|. The weight is what a cloth's springs hold at rest (a pinned corner's
springs carry about all of it) and twice it what a load dropped onto them can pull at most
(a weight let go on an unstretched spring stretches it twice as far as it hangs), so a
spring pulling harder than that is torn by the solver, not by the scene: the case of an
unconverged solve that lets a landing cloth stretch through its springs, whose energy can
stay inside the budget where the tear is local. A spring that holds no more than that may
stretch as far as the physics takes it: a soft cloth hanging under its own weight
(``scenes/strain_limiting.py``'s left cloth, at strain 1.2 and more) is stretched, not
torn. Without gravity the bound holds for every spring. A membrane triangle (a fabric's
measured stiffness) is held to the bound alone."""
import numpy as np

from ..scene import stability
from .budget import check_state
from ..errors import InstabilityError
from ..integrators.base import substep_count

_DEFAULT_HINT = ("try a smaller dt, more spring damping (k_d) or air drag, "
                 "or an implicit integrator")


class StepCheck:
    """The test of one simulator's states (its budget, diagnostics and bounds)."""

    def __init__(self, sim):
        self.sim = sim

    def verify(self, state, steps, t=None, dt=None):
        """None when the state reached by step steps + 1 is good, else the
        InstabilityError to raise for it; t and dt: the state's time and the step's length
        where it is a piece of a split step (``split.py``)."""
        sim = self.sim
        t = sim.time_at(steps + 1) if t is None else t
        stored, strain = sim.diagnostics.stored(state.x, t)
        stored = stored - sim.budget.floor if np.isfinite(stored) else np.inf
        bad = check_state(sim.budget, state.x, state.v, t, sim.position_bound,
                          sim.velocity_bound, stored)
        if bad >= 0:
            return self.error(steps, bad, stored, t=t, dt=dt)
        if sim.strain_bound is not None and strain is not None and \
                not strain <= sim.strain_bound:
            return self.error(steps, None, stored, strain, t, dt)
        return None

    def error(self, steps, code, stored=0.0, strain=None, t=None, dt=None):
        """The InstabilityError of step steps + 1 (the state after ``steps`` is kept):
        code < particles: a bad particle; code >= particles: the energy budget (code -
        particles the fastest particle); code None: the strain bound. t and dt: as for
        ``verify``."""
        sim = self.sim
        step = steps + 1
        t = sim.time_at(step) if t is None else t
        dt = sim.dt if dt is None else dt
        n = sim.model.particle_count
        if code is None:
            what = (f"stretched a spring or membrane triangle to strain {strain:.3g}, beyond "
                    f"strain_bound = {sim.strain_bound:g} (the cloth is torn, not stretched)")
        elif code < n:
            what = (f"left particle {code} non-finite or beyond |x| <= "
                    f"{sim.position_bound:g} m, |v| <= {sim.velocity_bound:g} m/s")
        else:
            budget = sim.budget
            what = (f"left more energy than the scene can supply (kinetic and "
                    f"gravitational, and {stored:.4g} J stored in springs, bending, "
                    f"membrane, pressure and contacts; limit {budget.limit(t):.4g} J from "
                    f"its energy {budget.values['baseline']:.4g} J at t = "
                    f"{budget.values['time']:.6g} s, budget.py; the fastest particle is "
                    f"{code - n})")
        return InstabilityError(
            f"step {step} (t = {t:.6g} s, dt = {dt:.3g} s) of integrator "
            f"'{sim.integrator_name}' {what}; the last good state (t = "
            f"{sim.time_at(steps):.6g} s) is kept. Hint: {self.hint()}.",
            step=step, time=t, integrator=sim.integrator_name)

    def hint(self):
        """What to change, for the simulator's integrator and scene."""
        sim = self.sim
        name, options = sim.integrator_name, sim.integrator.options
        if name in ("vbd", "xpbd") and options.get("substeps") != "auto":
            count = substep_count("auto", sim.dt, options["iterations"],
                                  stability.gershgorin_dt(sim.scene))
            if count > options["substeps"]:
                return (f"a Gauss-Seidel sweep carries a change one particle further, and a "
                        f"stress wave crosses this cloth's particles faster than "
                        f"{options['iterations']} sweeps a step can follow: give "
                        f"substeps='auto' ({count} here) or a smaller dt")
        if name in ("backward_euler", "projective", "vbd", "xpbd"):
            return ("try a smaller dt, more solver iterations (newton_iterations, "
                    "iterations) or more damping")
        if name != "forward_euler":
            return _DEFAULT_HINT
        if not (sim.scene.springs["damping"] > 0.0).any():
            return ("forward Euler gains energy at every dt on undamped springs: use "
                    "symplectic_euler, verlet or an implicit integrator")
        return (f"forward Euler is stable only well below the springs' explicit limit "
                f"(about {stability.gershgorin_dt(sim.scene):.2g} s here) and with enough "
                f"damping: use symplectic_euler, verlet or an implicit integrator")
