"""Physics terms, one module each (see ``base.py`` for what a term gives).

``TERMS`` is the order in which forces accumulate. ``build(model)`` makes the terms a
scene has, for one consumer (an integrator's workspace, the diagnostics).
"""
from .attraction import Attraction
from .base import Term
from .bending import Bending
from .colliders import Colliders
from .grab import Grab
from .membrane import Membrane
from .gravity_drag import GravityDrag
from .pressure import Pressure
from .self_contact import SelfContact
from .springs import Springs
from .wind import Wind

TERMS = (GravityDrag, Springs, Bending, Membrane, Wind, Attraction, Pressure, Colliders,
         SelfContact, Grab)


def build(model, select=None, contact=None, **options):
    """The present terms, in ``TERMS`` order; select(term class) -> bool filters them.
    Each term is given the ``options`` it declares (``Term.options``), and those that read
    the simulator's contact stage (``Term.reads_contact``) that stage, ``contact``."""
    made = []
    for cls in TERMS:
        if cls.present(model) and (select is None or select(cls)):
            given = {k: v for k, v in options.items() if k in cls.options}
            if cls.reads_contact:
                given["contact"] = contact
            made.append(cls(model, **given))
    return made


def find(terms, cls):
    """The term of class ``cls`` in ``terms``, or None."""
    return next((t for t in terms if isinstance(t, cls)), None)


__all__ = ["TERMS", "Term", "build", "find", "GravityDrag", "Springs", "Bending", "Membrane",
           "Wind", "Attraction", "Pressure", "Colliders", "SelfContact", "Grab"]
