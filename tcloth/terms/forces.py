"""Force evaluation over a scene's terms (``terms/``).

``Forces(model)`` is the workspace an integrator evaluates forces with: the terms the
scene has, each with its own scratch. ``compute(x, v, t, f_out)`` fills the force
accumulator f_out at the state (x, v) and time t, term by term in ``terms.TERMS`` order;
a term the scene lacks is not built, so nothing of it is compiled or launched.

The terms' ``accumulate`` functions run in one kernel launch (gravity and drag set f_out,
the others add to it); a term that needs Python between its loops (``in_kernel = False``:
self-contact's candidate list) is launched on its own between the kernels of the terms
before and after it, so that the order of the sums is always ``TERMS`` order.
``accumulate`` is that whole evaluation as a ``ti.func`` where every term is in-kernel or
gives an ``accumulate`` for batches (``in_batch``): the simulator's batches of substeps
call it (``batch.py``).
"""
import taichi as ti

from .. import terms as term_modules
from ..runtime import serial


@ti.data_oriented
class _Run:
    """Consecutive in-kernel terms evaluated by one kernel. init: "zero" (f_out = 0 first),
    "first" (the first term sets f_out) or None (every term adds)."""

    def __init__(self, terms, init):
        self.terms, self.init = terms, init

    @ti.func
    def accumulate(self, x, v, t, f_out):
        if ti.static(self.init == "zero"):
            ti.loop_config(serialize=ti.static(serial(f_out)))
            for p in range(f_out.shape[0]):
                f_out[p] = ti.Vector.zero(float, 3)
        for term in ti.static(self.terms):
            term.accumulate(x, v, t, f_out)


@ti.kernel
def _launch(run: ti.template(), x: ti.template(), v: ti.template(), t: float,
            f_out: ti.template()):
    run.accumulate(x, v, t, f_out)


@ti.data_oriented
class Forces:
    """The force terms of one model.

    Args:
        model: the Model.
        select: None (every term), or term class -> bool: which terms this workspace
            evaluates (projective leaves colliders to its projection, wind and attraction
            to the start of the step).
        contact: the simulator's contact stage (``Simulator.contact``), for the terms that
            read it (self-contact), or None.

    Attributes: terms (in ``TERMS`` order), first (the GravityDrag term or None), springs
    (the Springs term or None), runs (the launches of ``compute``: ``_Run``s of in-kernel
    terms and the other terms, in order).
    """

    def __init__(self, model, select=None, contact=None):
        terms = term_modules.build(model, select, contact)
        springs = term_modules.find(terms, term_modules.Springs)
        self.first = first = terms[0] if terms and isinstance(
            terms[0], term_modules.GravityDrag) else None
        order = list(terms)
        if springs is not None and first is not None and springs.sets_forces:
            # the first grid's gather sets f = gravity and drag + springs: one pass fewer
            terms[terms.index(springs)] = springs = term_modules.Springs(model, lead=first)
            order = [t for t in terms if t is not first]
        self.terms, self.springs = terms, springs
        if springs is not None:
            springs.grid_forces()
        self.runs = []
        init = "first" if first is not None else "zero"     # GravityDrag leads TERMS
        run = []
        for term in order:
            if term.in_kernel:
                run.append(term)
                continue
            self.runs.append(_Run(run, init))
            self.runs.append(term)
            run, init = [], None
        if run or not self.runs:
            self.runs.append(_Run(run, init))

    def batch_obstacle(self):
        """None when ``accumulate`` may run in a batch of substeps, else why not."""
        for term in self.terms:
            why = term.batch_obstacle() if term.in_kernel or term.in_batch else \
                f"{type(term).__name__} runs Python between its kernels"
            if why is not None:
                return why
        return None

    def compute(self, x, v, t, f_out):
        """f_out = the force on every particle at positions x, velocities v, time t."""
        for run in self.runs:
            if isinstance(run, _Run):
                for term in run.terms:
                    term.prepare(t)
                _launch(run, x, v, t, f_out)
            else:
                run.add_forces(x, v, t, f_out)

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """``compute`` as a ``ti.func``, where ``batch_obstacle()`` is None."""
        for run in ti.static(self.runs):
            run.accumulate(x, v, t, f_out)
