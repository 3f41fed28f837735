"""Where tcloth's moved modules went (the first layout's, and the base layer's since).

``import tcloth.simulator`` and ``from tcloth.budget import EnergyBudget`` keep working:
an old name gives the module at its new place (the same module object, so monkeypatching
either name patches both) with a DeprecationWarning naming that place. ``tcloth.scene``,
``tcloth.model`` and ``tcloth.render`` are packages now; each re-exports what its old
module was imported for.
"""
import importlib
import importlib.abc
import importlib.util
import sys
import warnings

MOVED = {
    "tcloth.builders": "tcloth.scene.builders",
    "tcloth.fabric": "tcloth.scene.fabric",
    "tcloth.hinges": "tcloth.scene.hinges",
    "tcloth.objfile": "tcloth.scene.objfile",
    "tcloth.stability": "tcloth.scene.stability",
    "tcloth.shapes": "tcloth.geometry.shapes",
    "tcloth.primitives": "tcloth.geometry.primitives",
    "tcloth.raycast": "tcloth.geometry.raycast",
    "tcloth.grid": "tcloth.model.grid",
    "tcloth.collider_table": "tcloth.model.collider_table",
    "tcloth.forces": "tcloth.terms.forces",
    "tcloth.simulator": "tcloth.sim.simulator",
    "tcloth.budget": "tcloth.sim.budget",
    "tcloth.diagnostics": "tcloth.sim.diagnostics",
    "tcloth.checkpoint": "tcloth.sim.checkpoint",
    "tcloth.constraints": "tcloth.sim.constraints",
    "tcloth.batch": "tcloth.sim.batch",
    "tcloth.instability": "tcloth.sim.instability",
    "tcloth.camera": "tcloth.render.camera",
    "tcloth.drawables": "tcloth.render.drawables",
    "tcloth.framing": "tcloth.render.framing",
    "tcloth.video": "tcloth.render.video",
    "tcloth.mesh": "tcloth.render.mesh",
    "tcloth.cli": "tcloth.app.cli",
    "tcloth.script": "tcloth.app.script",
    "tcloth.sweep": "tcloth.app.sweep",
    "tcloth.graph": "tcloth.geometry.graph",
    "tcloth.frontend": "tcloth.runtime.frontend",
    "tcloth.vulkan_probe": "tcloth.runtime.vulkan_probe",
}


def new_name(name):
    """The module's name now, or None where ``name`` is not an old one."""
    for old, new in MOVED.items():
        if name == old or name.startswith(old + "."):
            return new + name[len(old):]
    return None


class MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old module name and loads it as the module at its new place (first on
    ``sys.meta_path``: a moved package's old name must not find its files as new
    modules)."""

    def find_spec(self, name, path=None, target=None):
        if new_name(name) is None:
            return None
        return importlib.util.spec_from_loader(name, self)

    def create_module(self, spec):
        new = new_name(spec.name)
        warnings.warn(f"{spec.name} has moved to {new}", DeprecationWarning, stacklevel=2)
        return importlib.import_module(new)

    def exec_module(self, module):
        """The module ran at its new place."""


def install():
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, MovedFinder())
