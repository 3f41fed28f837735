"""The scene's optional features and the Scene methods that set them.

A feature (``base.Feature``) is optional scene data described once, in its module here:
bending, the membrane, the wind, attraction, pressure, self-collision, the strain limit and
tearing.
Each module holds the feature's scene-side validation (``set``), what a checkpoint saves of
it, and what the ``Model`` builds of it: an object of the feature's own class, kept as
``model.<feature name>`` (listed in the Model's docstring), that the terms and the solvers
read. The modules sit in the model's layer: they import neither the terms nor the
integrators (the term that takes a feature names it as its ``feature``).

``FEATURES`` lists them, in the order of their terms in ``terms.TERMS``, then the strain
limit and tearing (built last: it reads which of the others the model has). ``Model``
builds each from the scene, ``Model.refresh`` updates the live ones and ``checkpoint``
saves and loads each through its description, so a new term with scene data is its term
module, its feature module here and its place in ``FEATURES``.

Importing this package (``tcloth`` does, so every ``Scene`` has them) gives ``Scene`` a
method per feature, named by the feature, that validates its arguments and keeps the
result as ``scene.<feature name>`` (None until it is called).
"""
import functools

from ..scene.scene import Scene
from .attraction import ATTRACTION
from .bending import BENDING
from .membrane import MEMBRANE
from .pressure import PRESSURE
from .self_collision import SELF_COLLISION
from .strain_limit import STRAIN_LIMIT
from .tearing import TEARING
from .wind import WIND

FEATURES = (BENDING, MEMBRANE, WIND, ATTRACTION, PRESSURE, SELF_COLLISION, STRAIN_LIMIT,
            TEARING)


def _scene_method(feature):
    @functools.wraps(feature.set)
    def method(scene, *args, **kwargs):
        value = feature.set(scene, *args, **kwargs)
        setattr(scene, feature.name, value)
        return value
    method.__name__ = method.__qualname__ = feature.method
    return method


for _feature in FEATURES:
    setattr(Scene, _feature.name, None)
    setattr(Scene, _feature.method, _scene_method(_feature))
