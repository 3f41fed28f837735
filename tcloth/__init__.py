"""tcloth: a mass-spring cloth and particle-system sandbox on Taichi."""
import os

# Taichi prints a version banner on import; tcloth's output (e.g. `tcloth list`) stays clean
# unless the user asks for it.
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")

# after the environment default above; importing features gives Scene its methods
from . import features, grad, moved  # noqa: E402,F401
from .app import cli  # noqa: E402
from .errors import (ConvergenceWarning, DeviceWarning, GradientWarning,  # noqa: E402
                     InstabilityError, MissingExtraError, SceneError, StaleSimulatorError)
from .render.camera import Camera  # noqa: E402
from .render.mesh import export_mesh, write_obj, write_ply  # noqa: E402
from .render.render import Renderer, render  # noqa: E402
from .render.usd import UsdWriter, record_usd  # noqa: E402
from .render.video import record, write_png  # noqa: E402
from .runtime import device, init  # noqa: E402
from .scene.builders import Cloth, MeshCloth, Rope  # noqa: E402
from .scene.fabric import Fabric  # noqa: E402
from .scene.objfile import load_obj  # noqa: E402
from .scene.panel import Panel, panel  # noqa: E402
from .scene.scene import Scene  # noqa: E402
from .scene.usdfile import load_usd  # noqa: E402
from .sim.simulator import Simulator  # noqa: E402
from .version import __version__  # noqa: E402
from .viewer import view  # noqa: E402

moved.install()

__all__ = ["cli", "init", "device", "Scene", "Cloth", "MeshCloth", "Rope", "Fabric", "load_obj",
           "panel", "Panel", "load_usd", "Simulator", "SceneError", "InstabilityError", "ConvergenceWarning",
           "DeviceWarning", "GradientWarning", "MissingExtraError", "StaleSimulatorError",
           "Camera", "Renderer", "render", "record", "record_usd", "UsdWriter", "write_png",
           "export_mesh", "write_obj", "write_ply", "view", "__version__"]
