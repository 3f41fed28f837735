"""Force evaluation over a scene's terms (``terms/``).

``Forces(model)`` is the workspace an integrator evaluates forces with: the terms the
scene has, each with its own scratch. ``compute(x, v, t, f_out)`` fills the force
accumulator f_out at the state (x, v) and time t, term by term in ``terms.TERMS`` order;
a term the scene lacks is not built, so nothing of it is compiled or launched.
"""
from . import terms as term_modules


class Forces:
    """The force terms of one model.

    Args:
        model: the Model.
        select: None (every term), or term class -> bool: which terms this workspace
            evaluates (projective leaves colliders to its projection, wind and attraction
            to the start of the step).
    """

    def __init__(self, model, select=None):
        chosen = term_modules.build(model, select)
        # gravity and drag come first and set f; without them f starts at 0
        self.first = chosen[0] if chosen and isinstance(chosen[0], term_modules.GravityDrag) \
            else None
        self.terms = chosen[1:] if self.first is not None else chosen
        self.springs = term_modules.find(self.terms, term_modules.Springs)

    def compute(self, x, v, t, f_out):
        """f_out = the force on every particle at positions x, velocities v, time t."""
        fused = self.first is not None and self.springs is not None \
            and self.springs.sets_forces
        if self.first is None:
            f_out.fill(0)
        elif not fused:
            self.first.add_forces(x, v, t, f_out)
        for term in self.terms:
            if term is self.springs:
                term.add_forces(x, v, t, f_out, first=self.first if fused else None)
            else:
                term.add_forces(x, v, t, f_out)
