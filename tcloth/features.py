"""The scene's optional features and the Scene methods that set them.

A feature (``terms.base.Feature``) is optional scene data that one module owns: the wind,
attraction, pressure and self-collision of their terms, and the strain limit of
``constraints.py``. ``FEATURES`` lists them: every term's ``feature`` in ``terms.TERMS``
order, then the strain limit. ``Model`` builds each from the scene, ``Model.refresh``
uploads the live ones again and ``checkpoint`` saves and loads each through its
description, so a new term with scene data is its module and its place in ``TERMS``.

Importing this module (``tcloth`` does, so every ``Scene`` has them) gives ``Scene`` a
method per feature, named by the feature, that validates its arguments and keeps the
result as ``scene.<feature name>`` (None until it is called).
"""
import functools

from .constraints import STRAIN_LIMIT
from .scene import Scene
from .terms import TERMS

FEATURES = tuple(term.feature for term in TERMS if term.feature is not None) + (STRAIN_LIMIT,)


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
