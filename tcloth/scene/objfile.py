"""Wavefront OBJ in: vertex positions and faces, for cloth from any mesh.

Accepted: ``v x y z [w]``; ``vt u [v [w]]`` (texture coordinates); ``f`` with ``a``,
``a/b``, ``a/b/c`` or ``a//c`` references (the vertex index ``a`` and the texture
coordinate ``b``), 1-based or negative (relative to the vertices or texture coordinates
read so far); comments (``#``) and blank lines; ``o``, ``g``, ``s``, ``vn``, ``vp``,
``l``, ``usemtl``, ``mtllib`` lines, which carry nothing a cloth needs and are skipped.
Anything else, a non-number, an index out of range or a face of fewer than 3 vertices
raises ``SceneError`` naming the file, the line number and what is wrong.
"""
import numpy as np

from ..errors import SceneError

SKIPPED = {"o", "g", "s", "vn", "vp", "l", "usemtl", "mtllib"}


def load_obj(path):
    """(vertices (V,3) float64, faces: a list of tuples of 0-based vertex ids, each of
    3 or more; ``np.asarray(faces)`` is (F,3) for a triangle mesh)."""
    vertices, faces, _ = read_obj(path)
    return vertices, faces


def read_obj(path):
    """``load_obj``'s (vertices, faces) and the faces' texture coordinates: a list of
    (n, 2) float64 arrays, one (u, v) per corner of each face, or None where a face
    corner has none (``a`` or ``a//c``)."""
    try:
        with open(path) as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise SceneError(f"cannot read OBJ file {str(path)!r}: {e.strerror}") from None
    vertices, texture, faces, corners = [], [], [], []

    def fail(number, what):
        raise SceneError(f"{path}:{number}: {what}")

    def numbers(number, line, args, what):
        try:
            values = [float(a) for a in args]
        except ValueError:
            fail(number, f"a {what} is not a number: {line.strip()!r}")
        if not np.all(np.isfinite(values)):
            fail(number, f"a {what} is not finite: {line.strip()!r}")
        return values

    def index(number, k, read, what, plural):
        i = k - 1 if k > 0 else len(read) + k
        if k == 0 or not 0 <= i < len(read):
            fail(number, f"face {what} index {k} is out of range (there are "
                         f"{len(read)} {plural} so far)")
        return i

    for number, line in enumerate(lines, start=1):
        words = line.split("#", 1)[0].split()
        if not words or words[0] in SKIPPED:
            continue
        key, args = words[0], words[1:]
        if key == "v":
            if len(args) not in (3, 4):
                fail(number, f"a vertex needs 3 coordinates (got {len(args)}: {line.strip()!r})")
            vertices.append(numbers(number, line, args[:3], "vertex coordinate"))
        elif key == "vt":
            if not 1 <= len(args) <= 3:
                fail(number, f"a texture coordinate needs 1 to 3 numbers (got {len(args)})")
            texture.append((numbers(number, line, args, "texture coordinate") + [0.0])[:2])
        elif key == "f":
            if len(args) < 3:
                fail(number, f"a face needs at least 3 vertices (got {len(args)})")
            face, uv = [], []
            for ref in args:
                parts = ref.split("/")
                try:
                    k = [int(p) if p else None for p in parts[:2]]
                except ValueError:
                    fail(number, f"a face vertex is not an integer index: {ref!r}")
                if k[0] is None:
                    fail(number, f"a face vertex is not an integer index: {ref!r}")
                face.append(index(number, k[0], vertices, "vertex", "vertices"))
                if len(k) > 1 and k[1] is not None:
                    uv.append(texture[index(number, k[1], texture, "texture coordinate",
                                            "texture coordinates")])
            faces.append(tuple(face))
            corners.append(np.array(uv, dtype=np.float64) if len(uv) == len(face) else None)
        else:
            fail(number, f"unknown statement {key!r}")
    if not faces:
        raise SceneError(f"{path}: the file has no faces")
    uvs = None if any(c is None for c in corners) else corners
    return np.array(vertices, dtype=np.float64).reshape(-1, 3), faces, uvs
