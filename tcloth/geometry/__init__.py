"""Shapes in space: the collider shapes (``shapes.py``: signed distance, ray hit, normal,
mesh; one ``Shape`` entry each), triangle meshes of primitives (``primitives.py``) and
ray casting against triangles (``raycast.py``), and the index structures on a mesh's
particles that the features, terms and solvers share (``graph.py``: CSR layouts, greedy
colouring)."""
