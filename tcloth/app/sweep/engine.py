"""Running a sweep's cases: serially in this process, on a local pool of worker processes
(a Dask ``LocalCluster``), or on a Dask cluster at a scheduler address; finished cases on
disk so that a rerun with the same output folder skips them.

Output folder: ``cases/ID.json`` (one finished case, written atomically), ``references/
ID.npz``, ``results.csv`` (every case of the spec in order), ``metadata.json`` (the spec,
the package versions, the backend), and the plots.
"""
import contextlib
import csv
import datetime
import json
import math
import os
import signal
import threading
import uuid

import numpy as np

from ...sim.checkpoint import atomic_write
from ...errors import SceneError
from ...render.video import Progress
from . import worker
from .spec import Spec, count, load_spec

COLUMNS = ("stable", "first_bad_step", "error", "ms_per_step", "energy_drift", "max_strain",
           "steps", "t_end", "status", "reused", "id")


# statuses of cases that did not run to their end; not stored, so that a rerun runs them
FAILED = ("worker died", "not run", "reference failed")


class SweepError(SceneError):
    """A sweep that cannot run as asked (workers, scheduler); the message says why."""


def _atomic_write(path, write, mode="w"):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    atomic_write(path, write, mode)


class Store:
    """Finished cases and reference runs in an output folder."""

    def __init__(self, out):
        self.out = os.fspath(out)

    def _case_path(self, case_id):
        return os.path.join(self.out, "cases", case_id + ".json")

    def case(self, case_id):
        try:
            with open(self._case_path(case_id)) as f:
                return json.load(f)
        except (OSError, ValueError):
            return None

    def save_case(self, case_id, record):
        _atomic_write(self._case_path(case_id), lambda f: json.dump(record, f))

    def reference(self, ref_id, times):
        """The stored run's positions at every time in ``times``, else None."""
        try:
            with np.load(os.path.join(self.out, "references", ref_id + ".npz")) as z:
                stored = {float(k): z[k] for k in z.files}
        except (OSError, ValueError):
            return None
        return stored if all(t in stored for t in times) else None

    def save_reference(self, ref_id, positions):
        arrays = {repr(float(t)): x for t, x in positions.items()}
        _atomic_write(os.path.join(self.out, "references", ref_id + ".npz"),
                      lambda f: np.savez(f, **arrays), mode="wb")


@contextlib.contextmanager
def _sigint_ignored():
    """SIGINT ignored while the local pool's processes start: they inherit it (an ignored
    signal stays ignored across exec), so Ctrl-C in a terminal, which signals the whole
    process group, interrupts only this process, which then shuts the pool down (workers
    dying of it would make the shutdown wait for Dask's timeout and print its
    tracebacks)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _cores():
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


class Runner:
    """Where a sweep's cases run; reusable across sweeps (worker processes keep their
    compiled simulators).

    ``workers=1`` runs them in this process, re-initialising Taichi there as each case's
    precision asks (simulators made before go stale). ``workers=N`` runs them on N local
    processes, each with one Taichi runtime of ``threads`` CPU threads (default: cores / N,
    at least 1). ``scheduler="tcp://host:port"`` runs them on that Dask cluster, whose
    workers must run one thread each (``dask worker ADDRESS --nthreads 1 --nworkers K``)
    and see the scene script at the same path. Use as a context manager, or call
    ``close()``."""

    def __init__(self, workers=None, scheduler=None, threads=None, progress=True):
        for key, value in (("workers", workers), ("threads", threads)):
            if value is not None:
                count(key, value, SweepError)
        self.progress = progress
        self.client = self.cluster = None
        if scheduler is None and (workers or _cores()) == 1:
            self.backend = "serial"
            worker.set_threads(threads)
            return
        try:
            import dask
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise SweepError("running on several workers needs Dask: pip install "
                             "'tcloth[sweep]' (or run with workers=1)") from None
        if scheduler is None:
            workers = workers or _cores()
            threads = threads or max(1, _cores() // workers)
            with dask.config.set({"distributed.scheduler.allowed-failures": 0}), \
                    _sigint_ignored():
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                            processes=True, dashboard_address=None,
                                            memory_limit=0, silence_logs=50)
            self.client = Client(self.cluster)
            self.backend = f"local pool of {workers} processes x {threads} Taichi threads"
        else:
            try:
                self.client = Client(scheduler, timeout=30)
            except (OSError, TimeoutError) as e:
                raise SweepError(f"cannot reach the Dask scheduler {scheduler!r}: {e}") from None
            self.backend = f"Dask cluster at {scheduler}"
        info = self.client.scheduler_info()["workers"]
        if not info:
            self.close()
            raise SweepError(f"the Dask cluster at {scheduler!r} has no workers")
        for address, w in info.items():
            if w["nthreads"] != 1:
                self.close()
                raise SweepError(f"Dask worker {address} runs {w['nthreads']} threads; tcloth "
                                 "sweep needs one per worker process (dask worker ADDRESS "
                                 "--nthreads 1 --nworkers K)")
        self.workers = sorted(info)
        if threads is None:
            per_host = {}
            for w in info.values():
                per_host[w["host"]] = per_host.get(w["host"], 0) + 1
            cores = self.client.run(_cores)
            for address, w in info.items():
                self.client.run(worker.set_threads, max(1, cores[address] // per_host[w["host"]]),
                                workers=[address])
        else:
            self.client.run(worker.set_threads, threads)

    def close(self):
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        self.client = self.cluster = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def run(self, spec, out):
        """Run the spec's unfinished cases; write results.csv, metadata.json and the
        plots in ``out``; return the table's rows (dicts)."""
        spec = spec if isinstance(spec, Spec) else load_spec(spec)
        store = Store(out)
        cases = spec.cases()
        records = {c["id"]: store.case(c["id"]) for c in cases}
        todo = [c for c in cases if records[c["id"]] is None]
        references = {}
        for c in todo:
            if c["reference_id"] is not None:
                references.setdefault(c["reference_id"], (c["build"], set()))[1].add(c["t_end"])
        _write_metadata(spec, store, self.backend, len(cases), len(todo))
        bar = Progress(len(todo) + len(references), f"sweep {os.path.basename(spec.scene)}",
                       self.progress and bool(todo), unit="runs", rate_unit="runs/s")
        done = [0]

        def finish(case, record):
            if not record["status"].startswith(FAILED):
                store.save_case(case["id"], record)
            records[case["id"]] = record
            done[0] += 1
            bar.update(done[0])

        def reference_done(ref_id, times, positions):
            if "error" not in positions:
                store.save_reference(ref_id, positions)
            done[0] += 1
            bar.update(done[0])

        stored = {}
        for ref_id, (build, times) in references.items():
            stored[ref_id] = store.reference(ref_id, times)
        run = self._serial if self.client is None else self._dask
        run(spec, todo, references, stored, finish, reference_done)
        ran = {c["id"] for c in todo}
        rows = [_row(c, records[c["id"]], c["id"] not in ran) for c in cases]
        _write_csv(os.path.join(store.out, "results.csv"), rows)
        from .plots import plot_all
        plot_all(spec, rows, store.out)
        return rows

    @staticmethod
    def _serial(spec, todo, references, stored, finish, reference_done):
        for ref_id, (build, times) in references.items():
            if stored[ref_id] is None:
                stored[ref_id] = worker.run_reference(ref_id, spec.scene, spec.arch, build,
                                                      spec.reference, times)
            reference_done(ref_id, times, stored[ref_id])
        for case in _by_group(todo):
            ref = stored.get(case["reference_id"])
            finish(case, worker.run_case(case, ref))

    def _dask(self, spec, todo, references, stored, finish, reference_done):
        from dask.distributed import as_completed
        client = self.client
        token = uuid.uuid4().hex[:6]              # this run's task keys are its own

        homes = {}

        def home(key):
            # each reference and group its own worker in turn, while there are workers
            # left: a task queued on the worker of a case that kills its process dies
            # with it
            homes.setdefault(key, self.workers[len(homes) % len(self.workers)])
            return {"workers": [homes[key]], "allow_other_workers": True}

        ref_futures, owner, owner_futures = {}, {}, []
        for ref_id, (build, times) in references.items():
            if stored[ref_id] is None:
                fut = client.submit(worker.run_reference, ref_id, spec.scene, spec.arch, build,
                                    spec.reference, times, key=f"reference-{ref_id}-{token}",
                                    pure=False, **home(ref_id))
                owner[fut.key] = ("reference", ref_id, times)
                owner_futures.append(fut)
            else:
                fut = client.scatter(stored[ref_id])
                reference_done(ref_id, times, stored[ref_id])
            ref_futures[ref_id] = fut
        previous = {}
        for case in _by_group(todo):
            fut = client.submit(worker.run_case, case, ref_futures.get(case["reference_id"]),
                                previous.get(case["group"]), key=f"case-{case['id']}-{token}",
                                pure=False, **home(case["group"]))
            previous[case["group"]] = fut
            owner[fut.key] = ("case", case)
            owner_futures.append(fut)
        for fut in as_completed(owner_futures):
            kind, *what = owner[fut.key]
            if kind == "reference":
                ref_id, times = what
                result = (fut.result() if fut.status == "finished"
                          else {"error": f"reference failed: {_failure(fut)}"})
                reference_done(ref_id, times, result)
            else:
                finish(what[0], fut.result() if fut.status == "finished"
                       else worker.record_of(_failure(fut)))


def _failure(fut):
    """The status line of a task that did not finish."""
    from dask.distributed import KilledWorker
    if fut.status == "cancelled":
        return "not run: cancelled"
    exc = fut.exception()
    if isinstance(exc, KilledWorker):
        if exc.task == fut.key:
            return "worker died while running it"
        return f"not run: {exc.task} killed its worker first"
    return f"not run: {type(exc).__name__}: {exc}"


def _by_group(cases):
    """The cases with each group's (one simulator's) together, groups in the order of
    their first case, cases in spec order."""
    order = {}
    for c in cases:
        order.setdefault(c["group"], []).append(c)
    return [c for group in order.values() for c in group]


def _row(case, record, reused):
    row = {k: (json.dumps(v) if isinstance(v, (list, dict)) else v)
           for k, v in case["values"].items()}
    if record is None:
        record = worker.record_of("not run")
    row.update({k: record.get(k) for k in COLUMNS[:6]})
    row.update(steps=case["steps"], t_end=case["t_end"], status=record["status"],
               reused=reused, id=case["id"])
    return row


def _write_csv(path, rows):
    fields = list(dict.fromkeys(k for row in rows for k in row))

    def write(f):
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for row in rows:
            w.writerow({k: ("" if v is None or (isinstance(v, float) and math.isnan(v))
                            else v) for k, v in row.items()})
    _atomic_write(path, write)


def _write_metadata(spec, store, backend, total, todo):
    import taichi
    from ...version import __version__
    meta = {"tcloth": __version__, "taichi": ".".join(map(str, taichi.__version__)),
            "spec": spec.data, "scene": spec.scene, "backend": backend, "cases": total,
            "cases_to_run": todo,
            "started": datetime.datetime.now(datetime.timezone.utc).isoformat()}
    try:
        import dask
        meta["dask"] = dask.__version__
    except ImportError:
        pass
    _atomic_write(os.path.join(store.out, "metadata.json"),
                  lambda f: json.dump(meta, f, indent=1, default=repr))
