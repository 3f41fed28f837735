"""Where a frame-rate step's time goes, by part (issue 46: "where a step's time goes, by
part, before and after, in the doc; the cost per vertex-step beside OGC's published CPU
figure").

The fold of ``bench_self_collision.py --implicit`` (the saved 40 x 40 state resampled to
n x n, self-collision on) runs ``--steps`` steps at one step per frame with each of
``--integrators``, after four steps that compile kernels (from the same start). Python
timers wrap the contact stage's update points and the solvers' parts named in ``PARTS``:
kernels on CPUs return when they are done, so a call's wall time is its work (on a GPU
the tool synchronises around each). A part's time includes the parts it calls (the
nesting is in the labels), so the rows do not sum; ``step`` is the whole step.

Each integrator's lines: ``parts.<n>x<n>.<integrator>.<part>_ms`` (mean per step),
``.step_ms``, ``.us_per_vertex_step`` and ``.ogc_ratio``: that cost over Offset
Geometric Contact's published CPU figure, 0.21 s a step for 246K vertices (Chen et al.
2025), 0.85 us a vertex-step.

Usage: python tools/step_parts.py [--size 64] [--integrators projective,xpbd,vbd]
                                  [--steps 30] [--arch cpu|cuda]
"""
import argparse
import collections
import os
import time

import taichi as ti

import tcloth
from bench_self_collision import HERE, fold_scene, folded_state, resample
from benchcsv import integrator_spec
from tcloth.app.script import load_script
from tcloth.contact import broad, guard, stage
from tcloth.integrators import vbd

OGC_US_PER_VERTEX_STEP = 0.21 / 246e3 * 1e6
# (label, where, attribute): where is "stage" (the simulator's contact stage), "solver"
# (its integrator), an attribute path below one of them, or a module whose function the
# stage or a solver calls through it
PARTS = (
    ("begin_solve", "stage", "begin_solve"),
    ("follow_solve", "stage", "follow_solve"),
    ("truncate_solve", "stage", "truncate_solve"),
    ("end_step", "stage", "end_step"),
    ("end_step/candidates", "stage", "_step_candidates"),
    ("end_step/rounds", "stage", "_resolve"),
    ("end_step/cover", "stage", "_cover"),
    ("swept_search", stage, "search_step"),
    ("list_build", broad.BroadPhase, "build"),
    ("planes", guard, "planes"),
    ("near_planes", guard, "near_planes"),
    ("violations", guard, "violations"),
    ("keep_apart", guard, "keep_apart"),
    ("keep_apart", vbd, "keep_apart"),
    ("projective/planes", "solver", "_hold_planes"),
    ("projective/planes/gather", "solver.planes", "gather"),
    ("projective/planes/deflation", "solver.deflation", "prepare"),
    ("projective/cg", "solver.solver", "solve"),
    ("vbd/sweeps", "solver", "_sweep"),
)


def wrap(owner, name, label, totals, sync):
    """owner.name timed into totals[label]; returns an undo, or None where owner has no
    such attribute or it cannot be wrapped (a Taichi kernel of a data-oriented class)."""
    original = getattr(owner, name, None)
    if original is None:
        return None

    def timed(*args, **kwargs):
        sync()
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            sync()
            totals[label] += time.perf_counter() - start
    try:
        setattr(owner, name, timed)
    except (AttributeError, TypeError):
        return None
    return lambda: setattr(owner, name, original)


def resolve(sim, where):
    """The object a PARTS entry names."""
    if not isinstance(where, str):
        return where
    head, *rest = where.split(".")
    obj = sim.model.contact if head == "stage" else sim.integrator
    for attr in rest:
        obj = getattr(obj, attr, None)
    return obj


def parts_of(module, x40, v40, n, integrator, options, steps, sync):
    """{part: ms per step} of ``steps`` steps of the n x n fold at 1/60, and the whole
    step's."""
    scene = fold_scene(module, n)
    sim = tcloth.Simulator(scene, integrator, dt=1.0 / 60.0, **options)
    x, v = resample(x40, n), resample(v40, n)
    sim.set_state(positions=x, velocities=v)
    sim.step(4)
    sim.set_state(positions=x, velocities=v)
    totals = collections.defaultdict(float)
    undo = []
    for label, where, attr in PARTS:
        owner = resolve(sim, where)
        if owner is not None:
            undo.append(wrap(owner, attr, label, totals, sync))
    ran, start = 0, time.perf_counter()
    try:
        for _ in range(steps):
            sim.step()
            ran += 1
    except tcloth.InstabilityError as error:
        print(f"# {integrator} raised at step {ran + 1}: {str(error).splitlines()[0]}")
    finally:
        sync()
        wall = time.perf_counter() - start
        for restore in reversed([u for u in undo if u is not None]):
            restore()
    out = {f"{label}_ms": 1e3 * seconds / max(ran, 1) for label, seconds in totals.items()}
    out["step_ms"] = 1e3 * wall / max(ran, 1)
    out["steps"] = ran
    out["us_per_vertex_step"] = 1e6 * wall / max(ran, 1) / sim.model.particle_count
    out["ogc_ratio"] = out["us_per_vertex_step"] / OGC_US_PER_VERTEX_STEP
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--integrators", default="projective,xpbd,vbd")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--state", default=os.path.join(HERE, "data", "fold_40x40.npz"))
    args = ap.parse_args()
    if args.size < 2 or args.steps < 1:
        ap.error(f"--size must be at least 2 and --steps at least 1 (got {args.size}, "
                 f"{args.steps})")
    tcloth.init(arch=args.arch)
    sync = ti.sync if args.arch != "cpu" else (lambda: None)
    module = load_script(os.path.join(HERE, "..", "scenes", "fold.py"))[0]
    x40, v40 = folded_state(module, args.state)
    n = args.size
    for spec in args.integrators.split(","):
        integrator, options, label = integrator_spec(spec)
        print(f"# {label}: {args.steps} steps of the {n} x {n} fold at 1/60", flush=True)
        for key, value in parts_of(module, x40, v40, n, integrator, options, args.steps,
                                   sync).items():
            print(f"parts.{n}x{n}.{label}.{key}: {value:.4g}", flush=True)


if __name__ == "__main__":
    main()
