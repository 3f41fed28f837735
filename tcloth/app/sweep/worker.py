"""What runs in a sweep's worker process: one case, or one reference run.

Each process keeps its own Taichi runtime (re-initialised only when a case asks for
another arch, precision or thread count) and its last few simulators: the cases of one
group (all settings alike but dt) reuse one compiled simulator through ``reset(dt)``.
"""
import math
import time
from collections import OrderedDict

import numpy as np

from ... import runtime
from ..script import load_script
from ...errors import InstabilityError
from ...sim.simulator import Simulator

CACHED_SIMULATORS = 32


class _Process:
    threads = None
    runtime_key = None
    simulators = OrderedDict()


def set_threads(threads):
    """Taichi CPU threads of this process's cases (None: Taichi's default, every core)."""
    _Process.threads = threads


def _runtime(arch, precision):
    key = (arch, precision, _Process.threads, runtime.generation())
    if _Process.runtime_key != key:
        kwargs = {"cpu_max_num_threads": _Process.threads} if _Process.threads else {}
        runtime.init(arch=arch, precision=precision, **kwargs)
        _Process.runtime_key = (arch, precision, _Process.threads, runtime.generation())
        _Process.simulators.clear()


def _simulator(scene_path, arch, build, settings, group):
    """The group's simulator, reset to t = 0 with the settings' dt (built and compiled by
    two untimed steps when new)."""
    _runtime(arch, settings["precision"])
    sims = _Process.simulators
    if group in sims:
        sims.move_to_end(group)
        sim = sims[group]
    else:
        module, _ = load_script(scene_path)
        sim = Simulator(module.build(**build), settings["integrator"], dt=settings["dt"],
                        **{"split": False, **settings["options"]})
        try:
            sim.step(2)
        except InstabilityError:
            pass
        sims[group] = sim
        while len(sims) > CACHED_SIMULATORS:
            sims.popitem(last=False)
    sim.reset(settings["dt"])
    return sim


def run_reference(key, scene_path, arch, build, settings, times):
    """{t: (N,3) positions} of the reference run ``key`` at each time in ``times`` (the
    nearest multiple of its dt), or {"error": message} when it fails."""
    try:
        sim = _simulator(scene_path, arch, build, settings, key)
        out = {}
        for t in sorted(times):
            sim.step(max(0, round(t / sim.dt) - sim.num_steps))
            out[t] = sim.positions().astype(np.float64)
        return out
    except Exception as e:
        return {"error": f"reference failed: {type(e).__name__}: {e}"}


def record_of(status):
    """A case's record before anything is known of it: not stable, no numbers."""
    return {"stable": False, "first_bad_step": None, "error": math.nan,
            "ms_per_step": math.nan, "energy_drift": math.nan, "max_strain": math.nan,
            "status": status}


def run_case(case, reference=None, after=None):
    """One case's record: stable, first_bad_step, error (m), ms_per_step, energy_drift (J),
    max_strain, status. ``reference`` is run_reference's result. ``after`` is not read:
    on Dask it is the previous case of the group, a dependency that runs the group in
    order on the worker that holds its simulator."""
    record = record_of("ok")
    try:
        sim = _simulator(case["scene"], case["arch"], case["build"], case["settings"],
                         case["group"])
    except Exception as e:
        record["status"] = f"error: {type(e).__name__}: {e}"
        return record
    steps = case["steps"]
    e0 = sim.energy()["total"]
    strain, wall = sim.max_strain(), 0.0
    chunks = np.linspace(0, steps, min(case["samples"], steps) + 1).round().astype(int)
    try:
        for a, b in zip(chunks[:-1], chunks[1:]):
            t0 = time.perf_counter()
            sim.step(int(b - a))
            wall += time.perf_counter() - t0
            strain = max(strain, sim.max_strain())
    except InstabilityError as e:
        record.update(first_bad_step=e.step, status="unstable", max_strain=strain,
                      ms_per_step=1e3 * wall / max(sim.num_steps, 1))
        return record
    except Exception as e:
        record["status"] = f"error: {type(e).__name__}: {e}"
        return record
    drift = sim.energy()["total"] - e0
    record.update(ms_per_step=1e3 * wall / steps, energy_drift=drift, max_strain=strain,
                  stable=bool(math.isfinite(drift)))
    limit = case["energy_limit"]
    if limit is not None and not drift <= limit:
        record.update(stable=False, status="energy grew")
    if reference is not None:
        if "error" in reference:
            record["status"] = reference["error"]
        else:
            x_ref = reference[min(reference, key=lambda t: abs(t - case["t_end"]))]
            d = sim.positions().astype(np.float64) - x_ref
            record["error"] = float(np.sqrt(np.mean(np.sum(d * d, axis=1))))
    return record
