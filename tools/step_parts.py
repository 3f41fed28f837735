"""Where a frame-rate step's time goes, by part, and the cost per vertex-step beside OGC's
published CPU figure.

The fold of ``bench_self_collision.py --implicit`` (the saved 40 x 40 state resampled to
n x n, self-collision on) runs ``--steps`` steps at one step per frame with each of
``--integrators``, after four steps that compile kernels (from the same start). Python
timers wrap the contact stage's update points and the solvers' parts named in ``PARTS``:
kernels on CPUs return when they are done, so a call's wall time is its work (on a GPU
the tool synchronises around each). A part's time includes the parts it calls
(``<part>_ms``); its own time (``<part>_own_ms``) does not, and the own times with
``other_own_ms`` (the step's time in no part) sum to ``step_ms``, the whole step.
``--plot FILE`` draws the own times as one bar per integrator.

Each integrator's lines: ``parts.<n>x<n>.<integrator>.<part>_ms`` (mean per step),
``.step_ms``, ``.raised_at_step`` (where the solver raised ``InstabilityError``: the
means are then over the steps before), ``.us_per_vertex_step`` and ``.ogc_ratio``:
that cost over Offset Geometric Contact's published CPU figure, 0.21 s a step for 246K
vertices (Chen et al. 2025), 0.85 us a vertex-step.

Usage: python tools/step_parts.py [--size 64] [--integrators projective,xpbd,vbd]
                                  [--steps 30] [--arch cpu|cuda] [--plot FILE.png]
"""
import argparse
import collections
import os
import time

import taichi as ti

import tcloth
from bench_self_collision import HERE, fold_scene, folded_state, resample, warm_up
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


class Timers:
    """Each part's time with the parts it calls (``total``) and without them (``own``:
    the own times of every call partition the time spent in the parts)."""

    def __init__(self, sync):
        self.sync = sync
        self.total = collections.defaultdict(float)
        self.own = collections.defaultdict(float)
        self.stack = []         # per open call: the time its timed callees took

    def call(self, label, function, args, kwargs):
        self.sync()
        start = time.perf_counter()
        self.stack.append(0.0)
        try:
            return function(*args, **kwargs)
        finally:
            self.sync()
            spent = time.perf_counter() - start
            callees = self.stack.pop()
            self.total[label] += spent
            self.own[label] += spent - callees
            if self.stack:
                self.stack[-1] += spent


def wrap(owner, name, label, timers):
    """owner.name timed by ``timers`` as ``label``; returns an undo, or None where owner
    has no such attribute or it cannot be wrapped."""
    original = getattr(owner, name, None)
    if original is None:
        return None

    def timed(*args, **kwargs):
        return timers.call(label, original, args, kwargs)
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
    obj = sim.contact if head == "stage" else sim.integrator
    for attr in rest:
        obj = getattr(obj, attr, None)
    return obj


def parts_of(module, x40, v40, n, integrator, options, steps, sync):
    """{part: ms per step} of ``steps`` steps of the n x n fold at 1/60, and the whole
    step's."""
    scene = fold_scene(module, n)
    sim = tcloth.Simulator(scene, integrator, dt=1.0 / 60.0, **options)
    x, v = resample(x40, n), resample(v40, n)
    error = warm_up(sim, x, v)
    if error is not None:                       # torn in the warm-up: nothing to time
        print(f"# {integrator} raised at warm-up step {sim.num_steps + 1}: "
              f"{str(error).splitlines()[0]}")
        return {"raised_at_step": sim.num_steps + 1, "steps": 0}
    timers = Timers(sync)
    undo = []
    for label, where, attr in PARTS:
        owner = resolve(sim, where)
        restore = None if owner is None else wrap(owner, attr, label, timers)
        if restore is not None:
            undo.append(restore)
    ran, raised, start = 0, None, time.perf_counter()
    try:
        for _ in range(steps):
            sim.step()
            ran += 1
    except tcloth.InstabilityError as error:
        print(f"# {integrator} raised at step {ran + 1}: {str(error).splitlines()[0]}")
        raised = ran + 1
    finally:
        sync()
        wall = time.perf_counter() - start
        for restore in reversed(undo):
            restore()
    per_step = 1e3 / max(ran, 1)
    out = {}
    for label, seconds in timers.total.items():
        out[f"{label}_ms"] = seconds * per_step
        out[f"{label}_own_ms"] = timers.own[label] * per_step
    out["other_own_ms"] = (wall - sum(timers.own.values())) * per_step
    out["step_ms"] = wall * per_step
    out["steps"] = ran
    if raised is not None:
        out["raised_at_step"] = raised
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
    ap.add_argument("--plot", default=None, help="a PNG of the parts' own times")
    args = ap.parse_args()
    if args.size < 2 or args.steps < 1:
        ap.error(f"--size must be at least 2 and --steps at least 1 (got {args.size}, "
                 f"{args.steps})")
    tcloth.init(arch=args.arch)
    sync = ti.sync if args.arch != "cpu" else (lambda: None)
    module = load_script(os.path.join(HERE, "..", "scenes", "fold.py"))[0]
    x40, v40 = folded_state(module, args.state)
    n = args.size
    results = {}
    for spec in args.integrators.split(","):
        integrator, options, label = integrator_spec(spec)
        print(f"# {label}: {args.steps} steps of the {n} x {n} fold at 1/60", flush=True)
        results[label] = parts_of(module, x40, v40, n, integrator, options, args.steps, sync)
        for key, value in results[label].items():
            print(f"parts.{n}x{n}.{label}.{key}: {value:.4g}", flush=True)
    if args.plot:
        plot(results, n, args.plot)


def plot(results, n, path):
    """One horizontal bar per integrator that stepped: its step's own times by part, the
    parts below 2 % of every step in "other"."""
    results = {label: r for label, r in results.items() if r["steps"]}
    if not results:
        print("# nothing stepped: no plot")
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    own = {label: {key[:-len("_own_ms")]: value for key, value in r.items()
                   if key.endswith("_own_ms")} for label, r in results.items()}
    shown = sorted({part for label, parts in own.items() for part, ms in parts.items()
                    if part != "other" and ms >= 0.02 * results[label]["step_ms"]})
    fig, ax = plt.subplots(figsize=(11, 1.4 + 0.8 * len(results)))
    # tab20 without its greys, which "other" has
    colours = [c for c in plt.get_cmap("tab20").colors if max(c) - min(c) > 0.05]
    order = list(dict.fromkeys(label for label, _, _ in PARTS))    # a part's colour
    labels, labelled = list(results), set()
    for row, label in enumerate(labels):
        left = 0.0
        parts = own[label]
        rest = sum(ms for part, ms in parts.items() if part not in shown)
        for part in shown + ["other"]:
            ms = rest if part == "other" else parts.get(part, 0.0)
            if ms <= 0.0:
                continue
            ax.barh(row, ms, left=left, color="0.8" if part == "other" else
                    colours[order.index(part) % len(colours)],
                    label=None if part in labelled else part)
            labelled.add(part)
            left += ms
        r = results[label]
        raised = "" if "raised_at_step" not in r else \
            f", raised at step {r['raised_at_step']:.0f}"
        ax.text(left, row, f"  {r['step_ms']:.0f} ms, {r['us_per_vertex_step']:.1f} us a "
                f"vertex-step ({r['ogc_ratio']:.0f}x OGC){raised}", va="center", fontsize=8)
    ax.set_yticks(range(len(labels)), labels)
    ax.invert_yaxis()
    ax.set_xlabel("ms a step (each part's own time)")
    ax.set_title(f"{n} x {n} fold, one step per frame: where a step's time goes")
    ax.set_xlim(0, 1.6 * max(r["step_ms"] for r in results.values()))
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"# wrote {path}")


if __name__ == "__main__":
    main()
