"""The renderer draws the shipped scenes as the ray-casting renderer before it did: the
pictures in tests/data/render_golden.npz were drawn by that renderer (of every scene at
two moments, ``tools/render_golden.py``), and today's of the same states match them
within a tolerance. Rasterised edges, triangles' depths and lighting a pixel once where
its samples see one surface (docs/rendering.md) move a few pixels by more than rounding.
"""
import os

import numpy as np
import pytest

from tcloth.testing.golden import draw, posed
from tcloth.testing.scripts import scene_names, script

HERE = os.path.dirname(os.path.abspath(__file__))

DATA = os.path.join(HERE, "data", "render_golden.npz")
MEAN_LEVELS = 0.25     # the mean absolute difference over pixels and channels, of 255
FAR_LEVELS = 16        # a pixel is far off where a channel differs by more than this
FAR_SHARE = 0.002      # at most this share of a picture's pixels (38 of 160 x 120)
# the quick set's scene (a moving sphere through a cloth over the ground); the others,
# the mesh colliders' among them, take 20 to 150 s apiece with their kernels to build
QUICK = ("sphere_through_cloth",)
# the scenes drawn: between them every kind of thing the renderer draws (a grid cloth and
# a mesh cloth, one torn; particles alone and a rope; a plane, sphere, box, cylinder,
# capsule and body; a still, turning and deforming mesh collider). tools/render_golden.py
# keeps every scene's pictures; the other scenes draw these same things.
DRAWN = ("breathing", "cloth_on_box", "cloth_on_sphere", "drape", "garment", "incline",
         "orbit", "rope", "sphere_through_cloth", "table", "tearing", "turntable")


@pytest.fixture(scope="module")
def golden():
    with np.load(DATA) as data:
        return {key: data[key] for key in data.files}


def difference(a, b):
    """(mean absolute difference, share of pixels far off) between two pictures."""
    d = np.abs(a.astype(np.int32) - b.astype(np.int32))
    return float(d.mean()), float((d.max(axis=2) > FAR_LEVELS).mean())


def pictures(name, golden, **options):
    """Today's pictures of the stored states of scene ``name``."""
    module, cfg = script(name)
    dt, sim, out = float(golden[name + ".dt"]), None, []
    for steps, x in zip(golden[name + ".steps"], golden[name + ".positions"]):
        sim = posed(module, dt, steps, x, sim)
        out.append(draw(sim, cfg, **options))
    return out


@pytest.mark.parametrize("name", [n if n in QUICK else pytest.param(n, marks=pytest.mark.slow)
                                  for n in DRAWN])
def test_the_drawn_scenes_draw_as_before(f32, golden, name):
    for k, (now, before) in enumerate(zip(pictures(name, golden), golden[name + ".images"])):
        mean, far = difference(now, before)
        assert mean <= MEAN_LEVELS and far <= FAR_SHARE, (name, k, mean, far)


def test_the_drawn_scenes_are_shipped_scenes(golden):
    assert set(DRAWN) <= set(scene_names())
    assert all(name + ".images" in golden for name in DRAWN)


@pytest.mark.slow
def test_the_comparison_sees_a_change(f32, golden):
    """Without shadows, or a moment later, the same scene is not within the tolerance."""
    name = "cloth_on_sphere"
    shadowless = pictures(name, golden, shadows=False)[1]
    before = golden[name + ".images"]
    for other in (shadowless, before[0]):
        mean, far = difference(other, before[1])
        assert mean > MEAN_LEVELS or far > FAR_SHARE
