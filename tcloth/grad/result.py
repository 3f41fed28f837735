"""What a gradient run returns (``Trajectory.gradient``)."""
from typing import Any, Dict


class Result:
    """What ``Trajectory.gradient`` returns.

    Attributes: loss (float); grad (dict name -> NumPy array, or float for a scalar
    parameter); forward_seconds, backward_seconds (wall time of the forward run and of the
    backward run, which includes running each segment again); memory_bytes (the
    checkpoints and one segment's states, the memory the backward run keeps);
    adjoint_iterations (the adjoint solves' iterations in all: CG's for backward Euler,
    flexible GMRES's for projective dynamics); adjoint_residual (the largest relative
    residual an adjoint solve ended with); forward_residual (projective dynamics: the
    largest ``stats["residual"]`` of the forward run's steps, how far from its converged
    step, whose derivative the gradient is, the solver stopped); guarded_steps (the
    forward run's steps whose end the contact stage's guard changed in a way the
    gradient does not take: it is the solver's step's there, not the trajectory's);
    projected_steps (those whose end the guard's projection changed, differentiated as
    the projections they are: the corrections that fired frozen, their planes through
    the step's start; ``frozen.py``); unconverged_steps (projective dynamics' steps left
    above ``forward_tol``).
    """

    def __init__(self, loss: float, grad: Dict[str, Any], **stats: Any):
        self.loss, self.grad = loss, grad
        for key, value in stats.items():
            setattr(self, key, value)

    def __repr__(self):
        return (f"Result(loss={self.loss:.6g}, grad={sorted(self.grad)}, "
                f"forward_seconds={self.forward_seconds:.3g}, "
                f"backward_seconds={self.backward_seconds:.3g}, "
                f"memory_bytes={self.memory_bytes})")
