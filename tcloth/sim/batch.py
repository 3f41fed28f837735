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
"""
import taichi as ti

from ..integrators.linalg import copy


@ti.func
def _substep(integrator: ti.template(), limiter: ti.template(), contact: ti.template(),
             budget: ti.template(), a, b, t, dt, fresh, x_bound, v_bound):
    """One step of State a in place (b: scratch), with the contact stage's collider sweep
    and its check of the cloth's own pairs (``ContactStage.batch_begin`` /
    ``batch_end``); returns (the budget's ``check`` of the result: -1, a bad particle, or
    particles + the fastest one; the paths the sweep cut; whether the step needs the
    rest of the stage's guard from Python, and then no check)."""
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
    return bad, cut, unfinished


def kernel(integrator, limiter, contact, budget, a, b, start, x_bound, v_bound):
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
            bad, cut, unfinished = _substep(integrator, limiter, contact, budget, a, b, t,
                                            dt, evaluate, x_bound, v_bound)
            if unfinished:
                result = -2 - ti.cast(k, ti.i64)
                break
            if bad >= 0:
                result = ti.cast(k, ti.i64) * (2 * a.x.shape[0]) + bad
                break
        return result
    return run
