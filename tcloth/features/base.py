"""What a scene feature is (``Feature``), and the cloth selection the per-cloth ones share."""
import numpy as np

from ..errors import SceneError


class Feature:
    """Optional scene data, described once: from the Scene's method to the model's data
    and the checkpoint.

    ``tcloth.features`` gives ``Scene`` a method named ``method`` for each registered
    feature: it calls ``set`` (validation; its docstring is the method's) and keeps the
    result as ``scene.<name>`` (None until set). ``Model`` keeps ``build(model, value)`` as
    ``model.<name>``: an object of the feature's own class (its Taichi fields and what its
    readers need of the settings, listed in the Model's docstring), or None for nothing to
    simulate. ``Model.refresh`` calls ``refresh(data, value)`` for a ``live`` feature (the
    simulator's live setters change the scene's value, then refresh), which updates that
    object in place. A checkpoint stores ``saved(value)``, keyword arguments of the scene
    method that rebuild the value (NumPy arrays stored as arrays), and loads it by calling
    the method with them. ``floor`` bounds the feature's potential energy from below for
    the energy budget (``budget.py``).
    """
    name = None
    method = None
    live = False

    def set(self, scene, *args, **kwargs):
        raise NotImplementedError

    def saved(self, value):
        return dict(value)

    def build(self, model, value):
        raise NotImplementedError

    def refresh(self, data, value):
        """Nothing: only a ``live`` feature's data follows the scene's value."""

    def floor(self, value, scene):
        """The least potential energy (J) the feature can have: 0 (none below zero), or
        None where it has no lower bound."""
        return 0.0


def cloth_selection(scene, cloths, rest_positions):
    """(ids, rest) for a per-cloth feature's ``set``: the indices ``cloths`` into
    ``scene.cloths`` (None: every cloth) and the (N,3) rest positions of all particles
    (None: the scene's positions now), checked."""
    count = len(scene.cloths)
    ids = list(range(count)) if cloths is None else [int(c) for c in np.ravel(cloths)]
    if not ids or len(set(ids)) != len(ids) or min(ids) < 0 or max(ids) >= count:
        raise SceneError(f"cloths must be distinct indices into the scene's {count} cloths "
                         f"(got {cloths!r})")
    rest = scene.positions if rest_positions is None else \
        np.asarray(rest_positions, dtype=np.float64)
    if rest.shape != (scene.num_particles, 3) or not np.all(np.isfinite(rest)):
        raise SceneError(f"rest_positions must be finite ({scene.num_particles}, 3) "
                         f"positions (got shape {np.shape(rest_positions)})")
    return ids, rest.copy()
