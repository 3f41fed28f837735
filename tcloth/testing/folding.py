"""The self-contact fold (scenes/fold.py) that the self-collision benchmark and tests run
from one saved state: the 40 x 40 fold after 0.9 s, resampled bilinearly to n x n with the
contact thickness scaled with the spacing, and one simulated second of it at one step per
frame with self-collision on and off, with the worst crossing count over every step
(``crossings``). The fold is chaotic, so a change of rounding anywhere in the physics gives
another fold with other contacts; a saved state keeps the workload the same from one commit
to the next."""
import os
import time

import numpy as np

import tcloth

from .crossings import count_crossings


def folded_state(module, path, base=40, seconds=0.9):
    """(positions, velocities) of the 40 x 40 fold scene after ``seconds``, as (40, 40, 3):
    read from path, or computed and written to it."""
    if os.path.exists(path):
        with np.load(path) as data:
            return data["positions"], data["velocities"]
    sim = tcloth.Simulator(module.build(resolution=(base, base)), dt=2.5e-4)
    sim.step(int(seconds / 2.5e-4))
    x, v = sim.positions().reshape(base, base, 3), sim.velocities().reshape(base, base, 3)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez_compressed(path, positions=x, velocities=v)
    print(f"# wrote the folded state to {path}")
    return x, v


def fold_scene(module, n):
    """scenes/fold.py at n x n with the contact thickness scaled with the spacing (6 mm at
    40 x 40, the module docstring)."""
    return module.build(resolution=(n, n), thickness=0.006 * 40 / n)


def resample(grid, n):
    """Bilinear resampling of a (m, m, 3) grid to (n, n, 3)."""
    m = grid.shape[0]
    t = np.linspace(0, m - 1, n)
    i0 = np.minimum(np.floor(t).astype(int), m - 2)
    w = (t - i0)[:, None]
    rows = grid[i0] * (1 - w)[:, :, None] + grid[i0 + 1] * w[:, :, None]
    cols = rows[:, i0] * (1 - w.T)[:, :, None] + rows[:, i0 + 1] * w.T[:, :, None]
    return cols.reshape(-1, 3)


def warm_up(sim, x, v):
    """Four steps of ``sim`` from positions x and velocities v, which compile the kernels
    of both states' alternation, then the state set back to (x, v). Returns the
    InstabilityError where the cloth tore in them (at step ``sim.num_steps + 1``), else
    None."""
    try:
        sim.set_state(positions=x, velocities=v)
        sim.step(4)
    except tcloth.InstabilityError as error:
        return error
    sim.set_state(positions=x, velocities=v)
    return None


def one_second(module, x40, v40, n, integrator, dt, seconds, options):
    """The n x n fold from the saved state, ``seconds`` of simulated time at one step of
    dt per frame with ``integrator``, self-collision on and off: wall time (after four steps
    that compile, from the same start), CG iterations in all (where the solver counts
    them), the worst crossing count over every step (NumPy, ``crossings.py``), the contact
    stage's statistics (the warm-up's included)."""
    x, v = resample(x40, n), resample(v40, n)
    out = {}
    for mode in ("off", "on"):
        scene = fold_scene(module, n)
        if mode == "off":
            scene.self_collision = None
        sim = tcloth.Simulator(scene, integrator, dt=dt, **options)
        wall, worst = 0.0, 0
        if warm_up(sim, x, v) is not None:      # the cloth tore: say where, time nothing
            out[f"{mode}_raised_at_step"] = sim.num_steps + 1
            continue
        cg = 0
        for step in range(int(round(seconds / dt))):
            t = time.perf_counter()
            try:
                sim.step()
            except tcloth.InstabilityError:      # the cloth tore: say where, time no more
                out[f"{mode}_raised_at_step"] = step + 1
                break
            x1 = sim.positions()
            wall += time.perf_counter() - t
            cg += getattr(sim.integrator, "stats", {}).get("cg_iterations", 0)
            if mode == "on":        # every step's, untimed
                worst = max(worst, count_crossings(x1, scene.triangles))
        if cg:                  # the implicit solvers' conjugate-gradient iterations
            out[f"{mode}_cg_iterations"] = cg
        out[f"{mode}_wall_s"] = wall
        # how far the cloth came down, to see whether contact held it back
        out[f"{mode}_mean_height_m"] = float(sim.positions()[:, 1].mean())
        if mode == "on":
            out["crossings_max"] = worst
            stats = sim.contact_stats()
            for key in ("seconds", "failsafe_steps", "swept_searches", "solve_searches",
                        "rebuilds", "guard_corrections", "collider_paths_cut"):
                out[f"stage_{key}"] = stats[key]
    if not any(key.endswith("raised_at_step") for key in out):
        out["ratio"] = out["on_wall_s"] / out["off_wall_s"]
    return out
