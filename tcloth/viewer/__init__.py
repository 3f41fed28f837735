"""The live sandbox: a Taichi GGUI window that simulates a scene and draws it in real time.

Two layers:

  - ``Controls`` (no window, ``controls.py``): the panel's values and what they do to a
    ``Simulator`` (its live setters), picking and dragging a particle with the grab
    spring, pause / step / reset, the integrator switch, and the frame loop's instability
    handling and statistics. Tests drive it directly.
  - ``Viewer`` (``window.py``): the GGUI window (cloth with both face colours, particles,
    colliders, ground), the mouse and keys, and the panel that edits ``Controls.values``.

Beside them: ``display.py`` (whether a window can open here), ``camera.py`` (the orbit
camera and picking under the cursor) and ``meshes.py`` (NumPy meshes of the colliders and
the ground).
"""
from .camera import PICK_ANGLE, OrbitCamera, pick
from .controls import Controls, contact_lines
from .display import DisplayError, check_display, check_vulkan
from .meshes import collider_mesh, tiles, vertex_normals
from .window import BACKGROUND, PANEL_WIDTH, SIDE_OFFSET, Viewer, view

__all__ = ["Controls", "contact_lines", "OrbitCamera", "pick", "PICK_ANGLE", "DisplayError",
           "check_display", "check_vulkan", "vertex_normals", "tiles", "collider_mesh",
           "Viewer", "view", "BACKGROUND", "PANEL_WIDTH", "SIDE_OFFSET"]
