"""Wavefront OBJ in: vertex positions and faces, for cloth from any mesh.

Accepted: ``v x y z [w]``; ``f`` with ``a``, ``a/b``, ``a/b/c`` or ``a//c`` references
(only the vertex index is used), 1-based or negative (relative to the vertices read so
far); comments (``#``) and blank lines; ``o``, ``g``, ``s``, ``vn``, ``vt``, ``vp``,
``l``, ``usemtl``, ``mtllib`` lines, which carry nothing a cloth needs and are skipped.
Anything else, a non-number, an index out of range or a face of fewer than 3 vertices
raises ``SceneError`` naming the file, the line number and what is wrong.
"""
import numpy as np

from ..errors import SceneError

SKIPPED = {"o", "g", "s", "vn", "vt", "vp", "l", "usemtl", "mtllib"}


def load_obj(path):
    """(vertices (V,3) float64, faces: a list of tuples of 0-based vertex ids, each of
    3 or more; ``np.asarray(faces)`` is (F,3) for a triangle mesh)."""
    try:
        with open(path) as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise SceneError(f"cannot read OBJ file {str(path)!r}: {e.strerror}") from None
    vertices, faces = [], []

    def fail(number, what):
        raise SceneError(f"{path}:{number}: {what}")

    for number, line in enumerate(lines, start=1):
        words = line.split("#", 1)[0].split()
        if not words or words[0] in SKIPPED:
            continue
        key, args = words[0], words[1:]
        if key == "v":
            if len(args) not in (3, 4):
                fail(number, f"a vertex needs 3 coordinates (got {len(args)}: {line.strip()!r})")
            try:
                xyz = [float(a) for a in args[:3]]
            except ValueError:
                fail(number, f"a vertex coordinate is not a number: {line.strip()!r}")
            if not np.all(np.isfinite(xyz)):
                fail(number, f"a vertex coordinate is not finite: {line.strip()!r}")
            vertices.append(xyz)
        elif key == "f":
            if len(args) < 3:
                fail(number, f"a face needs at least 3 vertices (got {len(args)})")
            face = []
            for ref in args:
                try:
                    k = int(ref.split("/", 1)[0])
                except ValueError:
                    fail(number, f"a face vertex is not an integer index: {ref!r}")
                index = k - 1 if k > 0 else len(vertices) + k
                if k == 0 or not 0 <= index < len(vertices):
                    fail(number, f"face vertex index {k} is out of range (there are "
                                 f"{len(vertices)} vertices so far)")
                face.append(index)
            faces.append(tuple(face))
        else:
            fail(number, f"unknown statement {key!r}")
    if not faces:
        raise SceneError(f"{path}: the file has no faces")
    return np.array(vertices, dtype=np.float64).reshape(-1, 3), faces
