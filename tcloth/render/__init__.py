"""Pictures: the off-screen ray-cast renderer (``render.py``: ``Renderer``), its camera
(``camera.py``), what it draws (``drawables.py``: cloth drawn clear of colliders,
particles), the ground and framing (``framing.py``), video and PNG frames (``video.py``:
``record``) and meshes out (``mesh.py``: OBJ, PLY). ``tcloth.render`` the name is the
function that renders a simulator (``render.render``)."""
