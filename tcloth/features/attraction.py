"""``Scene.add_attraction`` and the model's attraction constants (``tcloth.terms.attraction``
has the force)."""
import numpy as np

from ..validate import as_scalar
from .base import Feature


class AttractionData:
    """The model's attraction (``model.attraction``).

    Attributes:
        G: the gravitational constant, N m^2/kg^2. softening: Plummer's eps, m.
    """

    def __init__(self, G, softening):
        self.G, self.softening = G, softening


class AttractionFeature(Feature):
    """``Scene.add_attraction``: (G, softening); the model's ``AttractionData``."""
    name, method = "attraction", "add_attraction"

    def set(self, scene, G, softening=0.0):
        """Inverse-square attraction between all particle pairs (O(n^2)):
        f_i = sum_j G m_i m_j (x_j - x_i) / (|x_j - x_i|^2 + softening^2)^(3/2), with
        potential -G m_i m_j / sqrt(r^2 + softening^2) reported as energy()["attraction"].

        Args: G (N m^2/kg^2) >= 0; softening (m) >= 0 (Plummer).
        """
        return (as_scalar("G", G, minimum=0.0), as_scalar("softening", softening, minimum=0.0))

    def saved(self, value):
        return {"G": value[0], "softening": value[1]}

    def build(self, model, value):
        return AttractionData(*value)

    def floor(self, value, scene):
        """-G (M^2 - sum m^2) / (2 softening): every pair at distance 0; None unsoftened."""
        G, softening = value
        if softening == 0.0:
            return None
        m = scene.masses
        return -G * (m.sum() ** 2 - np.sum(m * m)) / (2.0 * softening)


ATTRACTION = AttractionFeature()
