"""The repository's scene scripts (``scenes/*.py`` beside the package, in a checkout of
tcloth; an installed package has none), which the regression, golden-picture and stress
checks run as they ship."""
import glob
import os

from ..app.script import load_script

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))), "scenes")


def scene_names():
    """The names of the scene scripts, sorted."""
    return sorted(os.path.splitext(os.path.basename(p))[0]
                  for p in glob.glob(os.path.join(SCENES, "*.py")))


def script(name):
    """(module, CONFIG) of scenes/NAME.py."""
    return load_script(os.path.join(SCENES, name + ".py"))
