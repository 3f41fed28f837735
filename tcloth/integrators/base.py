"""Integrator base class: option parsing and the shared force evaluation."""
from ..errors import SceneError
from ..forces import compute_forces


class Integrator:
    """One entry point: ``simulate(model, state_in, state_out, dt)``, which also sets
    ``state_out.t = state_in.t + dt``.

    Subclasses list their options in ``defaults`` (name -> default); an unknown option
    raises SceneError naming it.
    """
    name = "integrator"
    defaults = {}

    def __init__(self, model, **options):
        unknown = sorted(set(options) - set(self.defaults))
        if unknown:
            raise SceneError(f"unknown option {unknown[0]!r} for integrator {self.name!r} "
                             f"(its options: {sorted(self.defaults) or 'none'})")
        self.options = {**self.defaults, **options}

    @staticmethod
    def forces_at(model, state):
        """Make ``state.f`` hold the forces at (state.x, state.v)."""
        if not state.forces_valid:
            compute_forces(model, state.x, state.v, state.f, state.t)
            state.forces_valid = True

    def simulate(self, model, state_in, state_out, dt):
        raise NotImplementedError
