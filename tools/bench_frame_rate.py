"""The frame-rate solvers at their defaults and one step per frame: do ordinary scenes run
their second, and at what cost? (docs/realtime.md, "One step per frame at the defaults").

Cases (``CASES``), each one simulated second at dt = 1/60:
  - ``capsule``: a 40 x 40 cloth of 0.6 m and 0.12 kg (structural springs of 1,200 N/m,
    the other families at their defaults, nothing pinned, self-collision 4 mm thick)
    dropped from 12 cm above a capsule of radius 4 cm lying along x; ``capsule_thin``:
    the same on a capsule of 1 cm;
  - ``stiff``: a 24 x 24 cloth of 0.8 m and 0.2 kg hanging from two corners, structural
    springs of 1e5 N/m;
  - ``thrown``: two 24 x 24 cloths thrown at each other at 3 m/s (``bench_contact.thrown``,
    self-collision);
  - ``fold``: ``scenes/fold.py`` (40 x 40, self-collision, a rod and the floor).
Each solver (``--solvers``) runs as a user gets it: its default options and the
simulator's defaults (split steps on). Checked with NumPy alone after every step: the
largest spring strain, edge-triangle crossings (``crossings.py``) and, for the capsule,
the particles inside it. "No energy beyond what the scene supplies" is the simulator's own
test (``sim/budget.py``), which would have raised.

Prints ``frame_rate.<case>.<solver>.<metric>: value`` lines: steps (of 60), raised (the
error's first words or none), peak_strain, crossings_max, inside_capsule_max,
split_steps, finest_split, retries, substeps (the solver's own, median), first_step_s (it
compiles the kernels), ms_per_step (median of the rest), slowest_step_s, wall_s (the rest),
wall_per_simulated_s.

``--split-cost``: what splitting costs where nothing fails: each case and solver as
simulators with the split on and off, stepped in turn (``--rounds`` rounds of ``--steps``
steps after a warm-up), printing ``frame_rate.<case>.<solver>.split_cost: ratio`` (the
medians' ratio, on over off).

Usage: python tools/bench_frame_rate.py [--cases capsule,stiff] [--solvers projective,vbd]
                                        [--csv docs/frame_rate.csv]
       python tools/bench_frame_rate.py --split-cost [--cases stiff] [--rounds 5]
"""
import argparse
import time

import numpy as np

import tcloth
from tcloth.testing.contact_cases import script_scene, thrown
from benchcsv import write_csv
from tcloth.testing.crossings import count_crossings, triangle_edges
from tcloth.integrators.base import substep_count

CAPSULE_AXIS = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def capsule(radius=0.04):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_cloth(resolution=(40, 40), size=(0.6, 0.6), center=(0.0, radius + 0.12, 0.0),
                    plane="xz", mass=0.12, structural=(1200.0, 0.05), pinned=[])
    scene.add_capsule(center=(0.0, 0.0, 0.0), radius=radius, half_height=0.4,
                      rotation=CAPSULE_AXIS)
    scene.set_self_collision(thickness=0.004)
    return scene, scene.positions, scene.velocities


def stiff():
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_cloth(resolution=(24, 24), size=(0.8, 0.8), center=(0.0, 1.0, 0.0), plane="xy",
                    mass=0.2, structural=(1e5, 0.05))
    return scene, scene.positions, scene.velocities


CASES = {
    "capsule": lambda: capsule(0.04),
    "capsule_thin": lambda: capsule(0.01),
    "stiff": stiff,
    "thrown": lambda: thrown(3.0)[:3],
    "fold": lambda: script_scene("fold")[:3],
}
SOLVERS = ("projective", "vbd", "xpbd")


def inside_capsules(scene, x):
    """How deep (m) the deepest particle is inside a capsule collider (0: none inside)."""
    deepest = 0.0
    for c in scene.colliders:
        if c["kind"] != "capsule":
            continue
        axis = np.asarray(c["rotation"])[:, 1]
        rel = x - np.asarray(c["center"])
        s = np.clip(rel @ axis, -c["half_height"], c["half_height"])
        distance = np.linalg.norm(rel - s[:, None] * axis, axis=1) - c["radius"]
        deepest = max(deepest, float(-distance.min()))
    return deepest


def strains(scene, x):
    pairs, rest = scene.springs["pairs"], scene.springs["rest_length"]
    return np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) / rest - 1.0


def solver_substeps(sim):
    """The substeps the solver takes in a step of the simulator's dt."""
    options = sim.integrator.options
    if "substeps" not in options:
        return 1
    return substep_count(options["substeps"], sim.dt, options["iterations"],
                         sim.integrator._explicit_limit)


def run(case, solver, dt=1 / 60, seconds=1.0):
    """One case with one solver at its defaults; a dict of metrics."""
    scene, x, v = CASES[case]()
    sim = tcloth.Simulator(scene, solver, dt=dt)
    sim.set_state(positions=x, velocities=v)
    triangles = scene.triangles
    edges = triangle_edges(triangles)
    steps = int(round(seconds / dt))
    peak, crossings, inside, times, substeps, raised = 0.0, 0, 0.0, [], [], None
    for k in range(steps):
        start = time.perf_counter()
        try:
            sim.step()
        except tcloth.InstabilityError as e:
            raised = str(e)
            break
        times.append(time.perf_counter() - start)
        substeps.append(solver_substeps(sim))
        x1 = sim.positions().astype(np.float64)
        peak = max(peak, float(strains(scene, x1).max()))
        crossings = max(crossings, count_crossings(x1, triangles, edges))
        inside = max(inside, inside_capsules(scene, x1))
    split = sim.step_stats()
    rest = times[1:]
    return {"steps": sim.num_steps, "raised": raised.split(";")[0] if raised else "none",
            "peak_strain": peak, "crossings_max": crossings, "inside_capsule_max": inside,
            "split_steps": split["split_steps"], "finest_split": split["finest"],
            "retries": split["retries"],
            "substeps": float(np.median(substeps)) if substeps else float("nan"),
            "first_step_s": times[0] if times else float("nan"),
            "ms_per_step": 1e3 * float(np.median(rest)) if rest else float("nan"),
            "slowest_step_s": float(np.max(rest)) if rest else float("nan"),
            "wall_s": float(np.sum(rest)),
            "wall_per_simulated_s": float(np.sum(rest)) / (len(rest) * dt) if rest
            else float("nan")}


def split_cost(case, solver, rounds=5, steps=10, dt=1 / 60):
    """(median ms a step with the split on, with it off): two simulators of one case,
    stepped ``steps`` at a time in turn after a warm-up step each."""
    sims = {}
    for split in (True, False):
        scene, x, v = CASES[case]()
        sims[split] = tcloth.Simulator(scene, solver, dt=dt, split=split)
        sims[split].set_state(positions=x, velocities=v)
        sims[split].step()
    times = {True: [], False: []}
    for _ in range(rounds):
        for split, sim in sims.items():
            for _ in range(steps):
                start = time.perf_counter()
                sim.step()
                times[split].append(time.perf_counter() - start)
    if any(sim.step_stats()["split_steps"] for sim in sims.values()):
        raise RuntimeError(f"{case} with {solver} split a step: not a case where nothing fails")
    return 1e3 * float(np.median(times[True])), 1e3 * float(np.median(times[False]))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--solvers", default=",".join(SOLVERS))
    ap.add_argument("--precision", default="f32")
    ap.add_argument("--csv", help="also write the rows to this CSV file")
    ap.add_argument("--split-cost", action="store_true",
                    help="measure what the split costs where nothing fails instead")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=10)
    args = ap.parse_args(argv)
    tcloth.init(arch="cpu", precision=args.precision)
    if args.split_cost:
        for case in args.cases.split(","):
            for solver in args.solvers.split(","):
                on, off = split_cost(case, solver, args.rounds, args.steps)
                print(f"frame_rate.{case}.{solver}.ms_split_on: {on:.3f}")
                print(f"frame_rate.{case}.{solver}.ms_split_off: {off:.3f}")
                print(f"frame_rate.{case}.{solver}.split_cost: {on / off:.3f}", flush=True)
        return
    rows = []
    for case in args.cases.split(","):
        for solver in args.solvers.split(","):
            result = run(case, solver)
            for key, value in result.items():
                shown = f"{value:.4g}" if isinstance(value, float) else value
                print(f"frame_rate.{case}.{solver}.{key}: {shown}", flush=True)
            rows.append({"case": case, "solver": solver, **result})
    if args.csv:
        write_csv(args.csv, rows)


if __name__ == "__main__":
    main()
