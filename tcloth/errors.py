"""Exceptions raised by tcloth."""


class SceneError(ValueError):
    """Bad input: the message names the argument and the offending value."""


class InstabilityError(RuntimeError):
    """A step produced a non-finite state or left the documented position bound.

    The simulator keeps the last good state (``positions()`` still reads it).
    Attributes: ``step`` (index of the failing step), ``time`` (s), ``integrator``.
    """

    def __init__(self, message, step=None, time=None, integrator=None):
        super().__init__(message)
        self.step = step
        self.time = time
        self.integrator = integrator


class StaleSimulatorError(RuntimeError):
    """A simulator was used after ``tcloth.init`` re-initialised Taichi."""


class ConvergenceWarning(UserWarning):
    """An implicit solver stopped at its iteration cap without converging; the step keeps
    its best iterate (backward Euler: the lowest incremental potential found)."""


class DeviceWarning(UserWarning):
    """A GPU was asked for and the CPU or a software (CPU) Vulkan driver was given."""


class MissingExtraError(ImportError):
    """An optional dependency is not installed; the message names tcloth's extra that
    brings it (e.g. usd-core: ``pip install -e ".[usd]"``)."""


class GradientWarning(UserWarning):
    """A gradient is not the trajectory's derivative at some of its steps (the result
    says which, e.g. ``Result.guarded_steps``: steps the contact guard changed)."""
