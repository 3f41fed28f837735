"""Steps that split instead of failing.

A step that fails the instability test (``instability.py``: a non-finite or unbounded
particle, more energy than the scene can supply, a spring past the strain bound) is
taken again from its start as 2 steps of dt / 2, then 4 of dt / 4, ... up to ``most``
pieces; only when the finest split fails too does the simulator raise InstabilityError,
keeping the state before the step. A split that passes stays in use for the steps after
it, and every ``RELAX`` steps that pass at a split the next is tried at half as many
pieces, down to the whole step: a landing or an impact costs its substeps while it lasts.

Why this is the physics and not a fudge: every integrator converges to the same motion as
its step shrinks (an explicit step by its order, an implicit or iterative solve because the
incremental potential's inertia m / h^2 grows against the stiffness, and a Gauss-Seidel
sweep then carries a stress wave further per substep), so a step that fails at dt and passes
at dt / k is the same simulation at a finer resolution in time; a scene that fails at every
split has no stable motion the integrator can find, and raises.

Nothing is copied where nothing fails: a step writes its end into the simulator's second
State, so a failed step leaves its start in place; only a split copies that start, once, to
come back to it when a finer split is needed.
"""
from ..errors import SceneError

# steps that pass at a split before the next is tried at half as many pieces
RELAX = 4


def check_split(split):
    """The most pieces a failing step is split into: an int >= 1 (1: never split), True
    (the default, ``DEFAULT``) or False (1)."""
    if split is True:
        return DEFAULT
    if split is False:
        return 1
    if isinstance(split, bool) or not isinstance(split, int) or split < 1:
        raise SceneError(f"split must be True, False or an int >= 1, the most pieces a "
                         f"failing step is split into (got {split!r})")
    return split


DEFAULT = 64


class StepSplitter:
    """The split of one simulator's steps: ``pieces`` now (1: whole steps), and the counts
    of ``stats()``. ``most``: the finest split (1: none)."""

    def __init__(self, sim, most):
        self.sim = sim
        self.most = most
        self.pieces = 1
        self._passed = 0          # steps passed at the current split since it was reached
        self._start = None        # a State holding a split step's start
        self.reset()

    def reset(self):
        """Counts from zero and whole steps (a new run: ``Simulator.reset``)."""
        self.pieces, self._passed = 1, 0
        self.counts = {"split_steps": 0, "pieces": 0, "retries": 0, "finest": 1}

    def stats(self):
        """dict: split_steps (steps taken as several pieces), pieces (the pieces they
        took), retries (failed attempts taken again finer), finest (the most pieces one
        step took), pieces_now (the split the next step starts with)."""
        return {**self.counts, "pieces_now": self.pieces}

    def saved(self):
        """What a checkpoint keeps, so that a loaded simulator splits as this one would."""
        return {"pieces": self.pieces, "passed": self._passed, "counts": dict(self.counts)}

    def restore(self, saved):
        """Take ``saved`` (``saved()``'s dict; None: a checkpoint from before splits)."""
        if saved:
            self.pieces, self._passed = int(saved["pieces"]), int(saved["passed"])
            self.counts.update({k: int(v) for k, v in saved["counts"].items()})

    def step(self, limiter):
        """One step of dt at the current split; splits it further where it fails."""
        sim = self.sim
        if self.pieces == 1:
            error = sim._advance(limiter)
            if error is None:
                return
            self.recover(error, limiter)
            return
        self._keep_start()
        self._split(self.pieces, limiter, None)

    def recover(self, error, limiter):
        """The step after the current state failed with ``error`` (the state before it
        kept): take it again as 2, 4, ... pieces, or raise ``error`` where splitting is off
        or cannot be taken (a gradient's run records every step)."""
        sim = self.sim
        if self.most == 1 or (sim.contact is not None and sim.contact.recording):
            raise error
        self.counts["retries"] += 1
        self._keep_start()
        self._split(2, limiter, error)

    def _split(self, pieces, limiter, first_error):
        """The step as ``pieces`` pieces, and finer while they fail; raises past ``most``."""
        error = first_error
        while True:
            if pieces > self.most:
                raise self._final(first_error or error, pieces // 2)
            error = self._pieces(pieces, limiter)
            if error is None:
                break
            self.counts["retries"] += 1
            self._restore_start()
            pieces *= 2
        self.counts["split_steps"] += 1
        self.counts["pieces"] += pieces
        self.counts["finest"] = max(self.counts["finest"], pieces)
        if pieces != self.pieces:
            self.pieces, self._passed = pieces, 0
        self._passed += 1
        if self._passed >= RELAX:
            self.pieces, self._passed = pieces // 2, 0

    def _pieces(self, pieces, limiter):
        """The step after the current state as ``pieces`` steps of dt / pieces, each
        checked. None (the step done and counted), or the error of the first bad piece
        (the state is the caller's to restore)."""
        sim = self.sim
        t0, h = sim.time, sim.dt / pieces
        for k in range(pieces):
            error = sim._advance(limiter, t0 + k * h, h)
            if error is not None:
                return error
        sim.num_steps += 1
        sim.state.t = sim.time
        return None

    def _keep_start(self):
        sim = self.sim
        if self._start is None:
            self._start = sim.model.state()
        for name in ("x", "v", "f"):
            getattr(self._start, name).copy_from(getattr(sim.state, name))

    def _restore_start(self):
        sim = self.sim
        for name in ("x", "v", "f"):
            getattr(sim.state, name).copy_from(getattr(self._start, name))
        sim.state.t = sim.time
        sim._state_changed()

    def _final(self, error, finest):
        """``error`` (the whole step's), its message saying the splits tried."""
        if finest > 1:
            error.args = (f"{error.args[0]} Split into 2 to {finest} steps of at least "
                          f"dt / {finest}, it failed too (Simulator's split).",)
        self.pieces, self._passed = 1, 0
        return error
