"""Parameter sweeps: a spec (TOML or dict) names a scene script, the settings and build
parameters to vary and a reference; every combination is one case, run serially, on a
local pool of processes, or on a Dask cluster, each finished case stored so that an
interrupted sweep resumes. ``tcloth sweep SPEC.toml --out DIR`` on the command line.

    from tcloth.app.sweep import run_sweep
    rows = run_sweep("spec.toml", "results/", workers=2)
"""
from .engine import Runner, SweepError
from .spec import Spec, SpecError, load_spec


def run_sweep(spec, out, workers=None, scheduler=None, threads=None, progress=True):
    """Run a sweep (a spec path, dict or Spec) into the folder ``out``; returns the rows
    of ``out/results.csv``. See ``Runner`` for workers, scheduler and threads."""
    spec = spec if isinstance(spec, Spec) else load_spec(spec)
    with Runner(workers=workers, scheduler=scheduler, threads=threads,
                progress=progress) as runner:
        return runner.run(spec, out)


__all__ = ["run_sweep", "Runner", "Spec", "SpecError", "SweepError", "load_spec"]
