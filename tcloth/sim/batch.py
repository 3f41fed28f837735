"""Batches of substeps: n steps of an explicit integrator in one kernel launch.

On a CPU, launching a kernel from Python costs more than a small cloth's substep takes to
compute, and a substep is a few launches (docs/benchmarks.md); a batch runs the n substeps
of ``Simulator.step(n)`` as one kernel whose outer loop walks the steps on one thread,
each step being the integrator's ``advance`` (the forces of every term, the update), the
strain limit and the instability check, all the same ``ti.func``s that a step from Python
launches one by one, so the results are the same numbers. The step works on the current
State in place (one copy of the step's code, which keeps the compile time of the batch
near that of the single step's kernels) with the other State as scratch, and a copy of the
batch's start state to go back to if a step goes bad.

A batch is used where every loop of a step would run on one thread anyway (on CPUs, below
``serial_below`` items: ``runtime.serial``) and no term needs Python between substeps
(``Simulator.fusion`` says why not otherwise: an implicit integrator, a Python-callable
gust, a GPU, a large scene). With self-collision the batch checks each step as the
contact stage would, and stops at a step that needs the stage's Python (a rebuild of
the proximity list, a pair to correct, a path a collider cut): the simulator finishes
that step with ``ContactStage.batch_finish`` and starts the next batch after it.
``Batches`` runs them for a simulator: it keeps their kernels and finds a batch's first
bad step.
"""
import taichi as ti

from ..integrators.linalg import copy


@ti.func
def _substep(integrator: ti.template(), limiter: ti.template(), contact: ti.template(),
             budget: ti.template(), tearing: ti.template(), a, b, t, dt, fresh, x_bound,
             v_bound):
    """One step of State a in place (b: scratch), with the contact stage's collider sweep
    and its check of the cloth's own pairs (``ContactStage.batch_begin`` /
    ``batch_end``), and the springs that break at its end where it checks good
    (``Tearing.tear``); returns (the budget's ``check`` of the result: -1, a bad
    particle, or particles + the fastest one; the paths the sweep cut, plus the springs
    that broke; whether the step needs the rest of the stage's guard from Python, and
    then no check)."""
    if ti.static(bool(contact)):
        contact.batch_begin(a.x)
    integrator.advance(a, b, t, dt, fresh)
    if ti.static(bool(limiter)):
        limiter.limit(a, ti.cast(1.0 / dt, float))
    cut, unfinished = 0, 0
    if ti.static(bool(contact)):
        cut, unfinished = contact.batch_end(a.x, a.v, ti.cast(t, float), ti.cast(dt, float))
    bad = -1
    if unfinished == 0:
        bad = budget.check(a.x, a.v, t + dt, x_bound, v_bound, 0.0)
        if ti.static(bool(tearing)):
            if bad < 0:
                cut += tearing.tear(a.x)       # a's forces are of the springs before
    return bad, cut, unfinished


def kernel(integrator, limiter, contact, budget, tearing, a, b, start, x_bound, v_bound):
    """The batch kernel of one configuration: ``run(n, fresh, time_base, steps_before, dt)``.

    Its objects are the closure's (compile-time constants), so a launch passes five
    scalars: every template argument adds to what Taichi's Python side spends on a
    launch (docs/benchmarks.md), and a batch is one launch per frame.

    ``run`` advances State a by n steps in place; b is scratch, and start gets a copy of a
    first. The time of step k's start is time_base + (steps_before + k) dt, in float64 as
    the simulator computes it. fresh: a's forces must be evaluated at the first step
    (Verlet; after a strain limit they always are). It returns -1, or k * 2 particles + c
    for the first step k whose result the energy budget's ``check`` finds bad (c: its
    code, below 2 particles): the batch stops there, a holds that bad state, and the
    caller goes back to ``start`` and runs the good steps again (the same numbers: the
    steps are deterministic). Or -2 - k where step k needs the rest of the contact
    stage's guard (``ContactStage.batch_finish``): a holds that step's end as the batch
    left it, unchecked, and the caller finishes it.
    """
    @ti.kernel
    def run(n: ti.i32, fresh: ti.i32, time_base: ti.f64, steps_before: ti.i32,
            dt: ti.f64) -> ti.i64:
        copy(start.x, a.x)
        copy(start.v, a.v)
        copy(start.f, a.f)
        result = ti.i64(-1)
        cut = 0
        ti.loop_config(serialize=True)
        for k in range(n):
            t = time_base + ti.cast(steps_before + k, ti.f64) * dt
            evaluate = fresh if k == 0 else 0
            if ti.static(bool(limiter)) or cut > 0:     # a's forces are of another state
                evaluate = 1
            bad, cut, unfinished = _substep(integrator, limiter, contact, budget, tearing,
                                            a, b, t, dt, evaluate, x_bound, v_bound)
            if unfinished:
                result = -2 - ti.cast(k, ti.i64)
                break
            if bad >= 0:
                result = ti.cast(k, ti.i64) * (2 * a.x.shape[0]) + bad
                break
        return result
    return run


class Batches:
    """A simulator's batches (``Simulator.step`` where ``fusion()`` is None): their
    kernels, one per (integrator, strain limiter, State) and contact list layout, and a
    State holding a batch's start."""

    def __init__(self, sim):
        self.sim = sim
        self.start = None
        self.mark = None     # the springs broken when the batch (or checked step) began
        # (integrator, limiter, State) -> (the contact stage's batch_key, its batch kernel)
        self.kernels = {}

    def forget(self):
        """Drop the kernels (the integrator or its options changed: they compile anew)."""
        self.kernels.clear()

    def run(self, n, limiter):
        """n steps in one launch, whose kernel checks every substep's
        particles and kinetic and gravitational energy; the stored energy and the strain
        are checked at the end, and where they fail the steps run again one at a time
        from the batch's start to find the first bad one. An integrator whose step costs
        many force passes (``Integrator.checked_steps``: VBD, XPBD) runs one step a launch,
        each checked whole. A step that needs the contact stage's Python ends the batch
        there (``_finish``). Returns the steps done."""
        sim = self.sim
        a, b = sim._states
        if self.start is None:
            self.start = sim.model.state()
        key = (sim.integrator, limiter, a)
        fields = sim.contact and sim.contact.batch_key()
        if key not in self.kernels or self.kernels[key][0] != fields:
            self.kernels[key] = fields, kernel(
                sim.integrator, limiter, sim.contact, sim.budget, sim._tearing, a, b,
                self.start, sim.position_bound, sim.velocity_bound)
        run = self.kernels[key][1]
        counts = sim.contact and sim.contact.batch_counts()
        self.mark = sim._tearing and sim._tearing.mark(synced=True)
        fresh = 0 if sim.integrator.holds_forces(a) else 1
        args = (fresh, sim._time_base, sim.num_steps - sim._step_base, sim.dt)
        done, error, changed = n, None, False
        if sim.integrator.checked_steps:
            done, error = self._checked_steps(run, a, n, args)
            code = -1
        else:
            code = run(n, *args)
        if code <= -2:      # step done needs the rest of the stage's guard
            done = -2 - code
            changed = self._finish(a, sim.num_steps + done)
            done += 1
            code = -1
        if code >= 0:
            done, bad = divmod(code, 2 * sim.model.particle_count)
            # a holds the bad state: checked whole, its stored energy in the message; the
            # steps before it again, each checked whole (the kernel checked S only)
            error = (sim._checker.verify(a, sim.num_steps + done)
                     or sim._checker.error(sim.num_steps + done, bad))
            self._restore_start(a, counts)
            done, earlier = self._checked_steps(run, a, done, args)
            error = earlier or error
        elif error is None and sim._checker.verify(a, sim.num_steps + done - 1) is not None:
            self._restore_start(a, counts)
            done, error = self._checked_steps(run, a, done, args)
        sim.num_steps += done
        sim.state.t = sim.time
        swept = sim.contact is not None and sim.contact.batch_cut_last()
        if limiter is None and error is None and not swept and not changed:
            sim.integrator.adopt_forces(sim.state)
        else:
            sim.integrator.invalidate()
        if sim._tearing is not None and sim._tearing.sync():
            sim.integrator.parameters_changed()      # the springs' values changed
            sim._rebase()
        if error is not None:
            raise error
        return done

    def _finish(self, a, steps):
        """The rest of the contact stage's guard (``ContactStage.batch_finish``) for step
        steps + 1, whose end a holds as a batch left it; whether it changed a."""
        sim = self.sim
        return sim.contact.batch_finish(a.x, a.v, sim.time_at(steps), sim.dt)

    def _restore_start(self, a, counts=None):
        """a, the contact stage's counts (``batch_counts``, where given) and the springs
        that held (``Tearing.rollback`` to ``mark``) as the batch started, for its steps
        to run again one at a time."""
        sim = self.sim
        for name in ("x", "v", "f"):
            getattr(a, name).copy_from(getattr(self.start, name))
        if counts:
            sim.contact.batch_replay(counts)
        if sim._tearing is not None:
            sim._tearing.rollback(self.mark)

    def _checked_steps(self, run, a, n, args):
        """n steps of the batch kernel ``run`` one at a time, each state checked with its
        stored energy and strain. Returns (good steps, the InstabilityError of the first
        bad one or None), State a at the last good state."""
        sim = self.sim
        fresh, time_base, before, dt = args
        for k in range(n):
            changed = False                                 # run keeps a's state as the start
            self.mark = sim._tearing and sim._tearing.mark()
            if run(1, fresh, time_base, before + k, dt) <= -2:
                changed = self._finish(a, sim.num_steps + k)
            error = sim._checker.verify(a, sim.num_steps + k)
            if error is not None:
                self._restore_start(a)
                return k, error
            fresh = 1 if changed or (sim.contact is not None
                                     and sim.contact.batch_cut_last()) else 0
        return n, None
