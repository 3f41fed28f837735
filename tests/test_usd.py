"""OpenUSD out and in, read back through usd-core's own ``pxr`` and checked by its
validators: the stage's points at frames 0, k and N are the simulator's (float32), its
topology, texture coordinates and pinned flags the cloths', its extents hold the points,
its colliders' transforms their motion; a mesh that pxr writes becomes the cloth the same
mesh gives from an OBJ; errors name the file and the prim. Blender's own importer opens
the stage (``tools/check_usd_blender.py``, where bpy is installed)."""
import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest

import tcloth
from tcloth import InstabilityError, MissingExtraError, SceneError
from tcloth.app import cli
from tcloth.render.drawables import FRONT_COLOUR
from tcloth.sim.checkpoint import scene_from_arrays, scene_to_arrays

from conftest import use_runtime

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
needs_pxr = pytest.mark.skipif(importlib.util.find_spec("pxr") is None,
                               reason="usd-core (pxr) is not installed: pip install -e "
                                      "\".[usd]\" (the test extra brings it)")
FRAMES, STEPS, DT, FPS = 6, 5, 1e-3, 24
SPHERE_VELOCITY = np.array([0.4, 0.0, -0.2])
TURN = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])     # 90 deg about z
TILT = np.array([[1.0, 0.0, 0.0], [0.0, 0.6, -0.8], [0.0, 0.8, 0.6]])     # about x
# two quads sharing an edge, their UVs cut along it (a seam: faceVarying)
STRIP = np.array([[0.0, 2.0, 0.0], [0.1, 2.0, 0.0], [0.2, 2.0, 0.0],
                  [0.0, 2.0, 0.1], [0.1, 2.0, 0.1], [0.2, 2.0, 0.1]])
STRIP_FACES = [(0, 3, 4, 1), (1, 4, 5, 2)]
STRIP_UVS = [np.array([[0, 0], [0, 1], [1, 1], [1, 0.0]]),
             np.array([[0, 0], [0, 1], [1, 1], [1, 0.0]])]


def moving_scene():
    """An 8 x 8 cloth over a moving sphere, a mesh cloth with a UV seam, a rope, a loose
    particle and a floor."""
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=0.5)
    scene.add_cloth(resolution=(8, 8), size=(0.6, 0.6), center=(0.0, 1.0, 0.0),
                    structural=(300.0, 0.05), shear=(30.0, 0.01), flexion=None,
                    pinned=[(0, 0), (7, 0)])
    scene.add_mesh_cloth(STRIP, STRIP_FACES, uvs=STRIP_UVS, structural=(100.0, 0.01),
                         flexion=None, pinned=[0])
    scene.add_rope((1.0, 1.5, 0.0), (1.0, 1.2, 0.0), 3, 0.05, 200.0)
    scene.add_particles([[-1.0, 1.0, 0.0]], mass=0.1)
    scene.add_sphere((0.0, 0.6, 0.0), 0.2, velocity=SPHERE_VELOCITY)
    scene.add_plane((0.0, -0.5, 0.0), (0.0, 1.0, 0.0))
    return scene


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """(sim, the .usda stage's path, the simulator's positions at every frame): the
    stage by ``record_usd``, the positions by stepping the reset simulator again."""
    pytest.importorskip("pxr", reason="usd-core (pxr) is not installed")
    use_runtime("f32", __name__)
    sim = tcloth.Simulator(moving_scene(), dt=DT)
    path = str(tmp_path_factory.mktemp("usd") / "scene.usda")
    stats = tcloth.record_usd(sim, path, frames=FRAMES, steps_per_frame=STEPS, fps=FPS,
                              progress=False)
    assert stats["frames"] == FRAMES and stats["path"] == path
    sim.reset()
    frames = [sim.positions()]
    for _ in range(FRAMES - 1):
        sim.step(STEPS)
        frames.append(sim.positions())
    return sim, path, frames


@pytest.fixture(scope="module")
def still(tmp_path_factory):
    """(sim, path) of a turned box, a tilted capsule and a cylinder beside the strip,
    written as one frame without a step (each collider shape a step would compile
    costs seconds)."""
    pytest.importorskip("pxr", reason="usd-core (pxr) is not installed")
    use_runtime("f32", __name__)
    scene = tcloth.Scene()
    scene.add_mesh_cloth(STRIP, STRIP_FACES, structural=(100.0, 0.01), flexion=None)
    scene.add_box((0.8, 0.2, 0.5), (0.1, 0.2, 0.3), rotation=TURN)
    scene.add_capsule((-0.8, 0.3, 0.5), 0.05, 0.2, rotation=TILT)
    scene.add_cylinder((-0.8, 0.3, -0.5), 0.1, 0.15)
    sim = tcloth.Simulator(scene, dt=DT)
    path = str(tmp_path_factory.mktemp("usd") / "still.usdc")
    writer = tcloth.UsdWriter(sim, path, fps=FPS)
    writer.write()
    writer.close()
    return sim, path


def open_stage(path):
    from pxr import Usd
    return Usd.Stage.Open(path)


def world_point(prim, local, code):
    """A prim-local point in the world at time code ``code`` (Gf acts on row vectors)."""
    from pxr import UsdGeom
    m = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(code))
    return np.append(local, 1.0) @ m


@needs_pxr
def test_points_normals_and_extents_follow_the_simulator(recorded):
    from pxr import UsdGeom
    sim, path, frames = recorded
    stage = open_stage(path)
    scene = sim.scene
    prims = [(UsdGeom.Mesh.Get(stage, f"/World/Cloths/cloth_{k}"), np.ravel(c.particles))
             for k, c in enumerate(scene.cloths)]
    prims += [(UsdGeom.BasisCurves.Get(stage, "/World/Ropes/rope_0"), scene.ropes[0].particles),
              (UsdGeom.Points.Get(stage, "/World/Particles"), np.array([scene.num_particles - 1]))]
    for prim, ids in prims:
        assert prim.GetPointsAttr().GetTimeSamples() == list(range(FRAMES))
        for code in (0, 3, FRAMES - 1):
            points = np.array(prim.GetPointsAttr().Get(code))
            np.testing.assert_array_equal(points, frames[code][ids].astype(np.float32))
            lo, hi = np.array(prim.GetExtentAttr().Get(code))
            assert np.all(lo <= points) and np.all(points <= hi)
    mesh, ids = prims[0]
    for code in (0, FRAMES - 1):
        normals = np.array(mesh.GetNormalsAttr().Get(code))
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, rtol=1e-6)
    assert mesh.GetNormalsInterpolation() == "vertex"
    moved = np.abs(frames[-1] - frames[0]).max()
    assert moved > 1e-3     # the cloth fell: later frames differ from the first


@needs_pxr
def test_topology_uvs_and_pinned_flags_are_the_cloths(recorded):
    from pxr import UsdGeom
    sim, path, _ = recorded
    stage = open_stage(path)
    for k, cloth in enumerate(sim.scene.cloths):
        mesh = UsdGeom.Mesh.Get(stage, f"/World/Cloths/cloth_{k}")
        tris = cloth.triangles - cloth.offset
        assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * len(tris)
        np.testing.assert_array_equal(np.array(mesh.GetFaceVertexIndicesAttr().Get()),
                                      tris.ravel())
        assert mesh.GetSubdivisionSchemeAttr().Get() == "none"
        primvars = UsdGeom.PrimvarsAPI(mesh.GetPrim())
        st = primvars.GetPrimvar("st")
        values = np.array(st.ComputeFlattened(), dtype=np.float64)
        corners = values[tris] if st.GetInterpolation() == "vertex" else values.reshape(-1, 3, 2)
        np.testing.assert_allclose(corners, cloth.uv, atol=1e-7)
        pinned = np.array(primvars.GetPrimvar("pinned").Get())
        np.testing.assert_array_equal(pinned, sim.scene.pinned[np.ravel(cloth.particles)])
        colour = np.array(primvars.GetPrimvar("displayColor").Get())
        np.testing.assert_allclose(colour, [FRONT_COLOUR], atol=1e-7)
    # the grid's UVs are one a vertex, the strip's seam needs one a corner
    assert [UsdGeom.PrimvarsAPI(UsdGeom.Mesh.Get(stage, f"/World/Cloths/cloth_{k}").GetPrim())
            .GetPrimvar("st").GetInterpolation() for k in (0, 1)] == ["vertex", "faceVarying"]
    np.testing.assert_array_equal(sim.scene.cloths[1].uv, [
        STRIP_UVS[face][corners] for face in (0, 1) for corners in ([0, 1, 2], [0, 2, 3])])
    rope = UsdGeom.BasisCurves.Get(stage, "/World/Ropes/rope_0")
    assert list(rope.GetCurveVertexCountsAttr().Get()) == [4]
    assert rope.GetTypeAttr().Get() == "linear"


@needs_pxr
def test_a_moving_collider_moves_as_simulated(recorded):
    from pxr import UsdGeom
    sim, path, _ = recorded
    stage = open_stage(path)
    sphere = stage.GetPrimAtPath("/World/Colliders/sphere_0")
    assert sphere.GetAttribute("xformOp:translate").GetTimeSamples() == list(range(FRAMES))
    for code in range(FRAMES):
        t = code * STEPS * DT
        np.testing.assert_allclose(world_point(sphere, np.zeros(3), code)[:3],
                                   np.array([0.0, 0.6, 0.0]) + t * SPHERE_VELOCITY, atol=1e-12)
    assert UsdGeom.Sphere(sphere).GetRadiusAttr().Get() == pytest.approx(0.2)
    plane = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Colliders/plane_1"))
    assert not plane.GetPrim().GetAttribute("xformOp:translate").GetTimeSamples()
    points = np.array([world_point(plane.GetPrim(), p, 0)[:3]
                       for p in np.array(plane.GetPointsAttr().Get())])
    np.testing.assert_allclose(points[:, 1], -0.5, atol=1e-7)
    assert np.ptp(points[:, 0]) > 10 * 0.6         # large: ten cloth widths and more


@needs_pxr
def test_turned_colliders_stand_where_the_scene_has_them(still):
    """A box corner, the capsule's top and the cylinder's size through their xformOps."""
    from pxr import UsdGeom
    _, path = still
    stage = open_stage(path)
    box = stage.GetPrimAtPath("/World/Colliders/box_0")
    assert UsdGeom.Cube(box).GetSizeAttr().Get() == 2.0
    np.testing.assert_allclose(world_point(box, np.ones(3), 0)[:3],
                               (0.8, 0.2, 0.5) + TURN @ (0.1, 0.2, 0.3), atol=1e-6)
    capsule = stage.GetPrimAtPath("/World/Colliders/capsule_1")
    assert UsdGeom.Capsule(capsule).GetAxisAttr().Get() == "Y"
    half = UsdGeom.Capsule(capsule).GetHeightAttr().Get() / 2
    np.testing.assert_allclose(world_point(capsule, (0.0, half, 0.0), 0)[:3],
                               (-0.8, 0.3, 0.5) + TILT[:, 1] * 0.2, atol=1e-6)
    cylinder = UsdGeom.Cylinder(stage.GetPrimAtPath("/World/Colliders/cylinder_2"))
    assert (cylinder.GetRadiusAttr().Get(), cylinder.GetHeightAttr().Get()) == \
        pytest.approx((0.1, 0.3))
    np.testing.assert_allclose(world_point(cylinder.GetPrim(), np.zeros(3), 0)[:3],
                               (-0.8, 0.3, -0.5), atol=1e-12)


@needs_pxr
def test_stage_says_y_up_metres_and_the_frame_rate(recorded):
    from pxr import UsdGeom
    _, path, _ = recorded
    stage = open_stage(path)
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == stage.GetFramesPerSecond() == FPS
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, FRAMES - 1)
    assert stage.GetDefaultPrim().GetPath() == "/World"


@needs_pxr
@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usdz", "still"])
def test_usd_validators_find_no_error(recorded, still, tmp_path, ext):
    """Every validator usd-core registers, through one ValidationContext."""
    from pxr import UsdValidation
    sim, path, _ = recorded
    if ext == "still":
        path, ext = still[1], ".usdc"
    elif ext != ".usda":
        sim.reset()
        path = str(tmp_path / f"scene{ext}")
        tcloth.record_usd(sim, path, frames=2, steps_per_frame=STEPS, progress=False)
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    assert len(validators) > 10
    errors = UsdValidation.ValidationContext(validators).Validate(open_stage(path))
    assert not [(e.GetName(), e.GetMessage()) for e in errors]
    assert not os.path.exists(path.replace(ext, ".partial" + ext))


@needs_pxr
def test_a_switched_off_collider_is_hidden_from_then_on(recorded, tmp_path):
    """``UsdWriter`` driven a frame at a time, as the viewer could: the sphere switched off
    after frame 0 and on again at frame 3 is invisible at frames 1 and 2 only."""
    from pxr import UsdGeom
    sim, _, _ = recorded
    sim.reset()
    writer = tcloth.UsdWriter(sim, str(tmp_path / "live.usdc"), fps=FPS)
    for frame in range(4):
        sim.set_collider_enabled(0, frame not in (1, 2))
        writer.write()
        sim.step(1)
    writer.close()
    sim.set_collider_enabled(0, True)
    stage = open_stage(str(tmp_path / "live.usdc"))
    sphere = UsdGeom.Sphere.Get(stage, "/World/Colliders/sphere_0")
    assert [sphere.ComputeVisibility(k) for k in range(4)] == \
        ["inherited", "invisible", "invisible", "inherited"]
    plane = UsdGeom.Mesh.Get(stage, "/World/Colliders/plane_1")
    assert not plane.GetVisibilityAttr().HasAuthoredValue()


@needs_pxr
def test_an_unstable_run_keeps_its_good_frames(recorded, tmp_path, monkeypatch):
    sim, _, _ = recorded
    sim.reset()
    steps = []

    def step(n=1):
        steps.append(n)
        if len(steps) == 3:
            raise InstabilityError("blew up.", step=sim.num_steps)
    monkeypatch.setattr(sim, "step", step)
    path = str(tmp_path / "unstable.usdc")
    with pytest.raises(InstabilityError, match=r"Kept 3 good frames in .*unstable\.usdc"):
        tcloth.record_usd(sim, path, frames=FRAMES, steps_per_frame=STEPS, progress=False)
    assert open_stage(path).GetEndTimeCode() == 2


def write_pxr_mesh(path, up="Y", metres=1.0, left_handed=False):
    """The STRIP (two quads) and a triangle, with face-varying UVs, under a translated
    Xform, written by pxr alone (not by tcloth)."""
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, metres)
    UsdGeom.Xform.Define(stage, "/Root").AddTranslateOp().Set(Gf.Vec3d(0.5, 0.0, 0.0))
    stage.DefinePrim("/Root/Looks", "Scope")
    mesh = UsdGeom.Mesh.Define(stage, "/Root/strip")
    points = np.vstack([STRIP, [[0.3, 2.0, 0.0]]])
    faces = STRIP_FACES + [(2, 5, 6)]
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr([len(f) for f in faces])
    indices = [i for f in faces for i in (f[::-1] if left_handed else f)]
    mesh.CreateFaceVertexIndicesAttr(indices)
    if left_handed:
        mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    uv = np.vstack(STRIP_UVS + [[[0, 0], [1, 0], [0.5, 1]]])
    if left_handed:
        uv = np.vstack([u[::-1] for u in STRIP_UVS] + [[[0.5, 1], [1, 0], [0, 0]]])
    UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying).Set(
        Vt.Vec2fArray.FromNumpy(uv.astype(np.float32)))
    UsdGeom.Mesh.Define(stage, "/Root/empty").CreatePointsAttr([(0, 0, 0)])
    stage.GetRootLayer().Save()
    return points, faces


def write_obj(path, points, faces):
    """The same mesh as an OBJ with texture coordinates (one ``vt`` a face corner)."""
    corners = [[0, 0], [0, 1], [1, 1], [1, 0]] * 2 + [[0, 0], [1, 0], [0.5, 1]]
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in points]
    lines += [f"vt {u} {v}" for u, v in corners]
    starts = np.cumsum([0] + [len(f) for f in faces])
    lines += ["f " + " ".join(f"{i + 1}/{s + c + 1}" for c, i in enumerate(f))
              for f, s in zip(faces, starts)]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


@needs_pxr
@pytest.mark.parametrize("up, metres, left", [("Y", 1.0, False), ("Z", 0.01, True)])
def test_a_pxr_mesh_becomes_the_cloth_its_obj_gives(tmp_path, up, metres, left):
    """Vertices (through the Xform, in metres, y up), faces and UVs as from the OBJ; a Z-up
    stage in centimetres (Blender's way) and a left-handed mesh read the same."""
    usd = str(tmp_path / "mesh.usda")
    points, faces = write_pxr_mesh(usd, up, metres, left)
    obj = str(tmp_path / "mesh.obj")
    expected = np.float32(points).astype(float) + (0.5, 0.0, 0.0)   # through the Xform
    write_obj(obj, expected, faces)
    if up == "Z":           # z up in the file is y up once read; centimetres to metres
        expected = np.stack([expected[:, 0], expected[:, 2], -expected[:, 1]], 1) * metres
    scene = tcloth.Scene()
    from_usd = scene.add_mesh_cloth(usd, structural=(100.0, 0.0), flexion=None,
                                    prim="/Root/strip")
    from_obj = scene.add_mesh_cloth(obj, structural=(100.0, 0.0), flexion=None)
    x = scene.positions
    n = len(points)
    np.testing.assert_allclose(x[:n], expected, rtol=1e-12, atol=1e-12)
    if up == "Y":
        np.testing.assert_array_equal(x[:n], x[n:])
    np.testing.assert_array_equal(from_usd.triangles - from_usd.offset,
                                  from_obj.triangles - from_obj.offset)
    np.testing.assert_allclose(from_usd.uv, from_obj.uv, atol=1e-7)
    # the default prim is the first Mesh: the same strip
    first = tcloth.load_usd(usd)
    np.testing.assert_array_equal(first[0], x[:n])
    assert first[1] == [tuple(f) for f in faces]


@needs_pxr
@pytest.mark.parametrize("prim, message", [
    ("/Root/Looks", r"mesh\.usda: prim '/Root/Looks' is a Scope, not a Mesh"),
    ("/Root/nothing", r"mesh\.usda: prim '/Root/nothing' does not exist"),
    ("/Root/empty", r"mesh\.usda: prim '/Root/empty': the mesh has no faces"),
    ("Root/strip", r"prim must be an absolute prim path .*'Root/strip'")])
def test_import_errors_name_the_file_and_the_prim(tmp_path, prim, message):
    usd = str(tmp_path / "mesh.usda")
    write_pxr_mesh(usd)
    with pytest.raises(SceneError, match=message):
        tcloth.Scene().add_mesh_cloth(usd, prim=prim)


@needs_pxr
def test_unreadable_files_and_misplaced_prims_are_refused(tmp_path):
    bad = tmp_path / "bad.usda"
    bad.write_text("#usda 1.0\n(\n  nonsense\n")
    with pytest.raises(SceneError, match=r"^cannot read USD file '.*bad\.usda': .*bad\.usda:"):
        tcloth.load_usd(str(bad))
    with pytest.raises(SceneError, match="cannot read USD file .*: no such file"):
        tcloth.load_usd(str(tmp_path / "none.usdc"))
    empty = tmp_path / "empty.usda"
    empty.write_text("#usda 1.0\n")
    with pytest.raises(SceneError, match=r"empty\.usda: the file has no Mesh prim"):
        tcloth.load_usd(str(empty))
    with pytest.raises(SceneError, match="prim names a mesh in a USD file"):
        tcloth.Scene().add_mesh_cloth(os.path.join(ROOT, "scenes", "assets", "curtain.obj"),
                                      prim="/x")


@needs_pxr
def test_export_errors_name_the_path(recorded, tmp_path):
    sim, _, _ = recorded
    blocker = tmp_path / "file"
    blocker.write_text("")
    (tmp_path / "folder.usda").mkdir()
    for path, message in [(str(blocker / "scene.usda"), "cannot write USD file .*scene.usda"),
                          (str(tmp_path / "scene.abc"), r"must end in \.usd, \.usda, "),
                          (str(tmp_path / "folder.usda"), "cannot write USD file .*: it is a "
                                                          "folder")]:
        with pytest.raises(SceneError, match=message):
            tcloth.UsdWriter(sim, path)


FALLING = ('"""A cloth falls."""\n'
           "import tcloth\n"
           'CONFIG = {"dt": 1e-3, "steps_per_frame": 5, "frames": 4}\n'
           "def build(mesh=None, prim=None):\n"
           "    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))\n"
           "    if mesh:\n"
           "        scene.add_mesh_cloth(mesh, prim=prim, structural=(300.0, 0.05),\n"
           "                             flexion=None)\n"
           "    else:\n"
           "        scene.add_cloth(resolution=(8, 8), size=(0.6, 0.6), center=(0, 1, 0),\n"
           "                        structural=(300.0, 0.05), shear=(30.0, 0.01), flexion=None)\n"
           "    return scene\n")


@needs_pxr
def test_render_usd_alone_and_its_errors_on_the_command_line(recorded, tmp_path, capsys,
                                                             monkeypatch):
    """``tcloth render SCRIPT --usd PATH`` without --out writes the stage and no video;
    a bad path, and a script whose USD prim is not a mesh: exit code 2, one line naming
    the file and the prim. (Taichi is not initialised again: the module's runtime runs.)"""
    monkeypatch.setattr(cli, "init", lambda arch, precision: None)
    script = tmp_path / "falling.py"
    script.write_text(FALLING)
    usd = tmp_path / "out" / "falling.usdc"
    monkeypatch.chdir(tmp_path)
    assert cli.main(["render", str(script), "--usd", str(usd), "--quiet"]) == 0
    assert open_stage(str(usd)).GetEndTimeCode() == 3 and not os.path.exists("out/falling.mp4")
    mesh = str(tmp_path / "mesh.usda")
    write_pxr_mesh(mesh)
    capsys.readouterr()
    cases = [(["--usd", str(tmp_path / "falling.py" / "x.usdc")], "cannot write USD file"),
             (["--usd", str(usd), "--set", f"mesh={mesh!r}", "--set", "prim='/Root/Looks'"],
              f"{mesh}: prim '/Root/Looks' is a Scope, not a Mesh")]
    for args, message in cases:
        assert cli.main(["render", str(script), *args, "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("tcloth: error: ") and message in err[0], err


def test_without_usd_core_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pxr.Usd", None)     # import pxr.Usd raises ImportError
    with pytest.raises(MissingExtraError, match=r"usd-core.*'usd': pip install -e \"\.\[usd\]\""):
        tcloth.load_usd("scene.usda")


def test_checkpoints_keep_a_mesh_cloths_uvs():
    scene = tcloth.Scene()
    scene.add_mesh_cloth(STRIP, STRIP_FACES, uvs=STRIP_UVS, structural=(1.0, 0.0), flexion=None)
    desc, arrays = scene_to_arrays(scene)
    np.testing.assert_array_equal(scene_from_arrays(desc, arrays).cloths[0].uv,
                                  scene.cloths[0].uv)


BPY_PYTHON = "/work/bpyvenv/bin/python"


@pytest.mark.slow
def test_blender_imports_the_stage_with_the_simulated_positions(tmp_path):
    """tools/check_usd_blender.py: Blender's own USD importer (bpy), headless; each cloth
    has the simulator's vertex count and, at frames 0 and N, its positions within 1e-5 m
    after Blender's axis conversion; Blender's own export of it (z up) reads back into
    tcloth at those positions."""
    if importlib.util.find_spec("pxr") is None:
        pytest.skip("usd-core (pxr) is not installed: pip install -e \".[usd]\"")
    python = os.environ.get("TCLOTH_BPY_PYTHON") or (BPY_PYTHON if os.path.exists(BPY_PYTHON)
                                                     else None)
    if python is None and importlib.util.find_spec("bpy") is None:
        pytest.skip("Blender's Python module bpy is not installed (it needs Python 3.11: "
                    "python3.11 -m venv /work/bpyvenv && /work/bpyvenv/bin/pip install bpy, "
                    "or set TCLOTH_BPY_PYTHON)")
    res = subprocess.run([sys.executable, os.path.join(ROOT, "tools", "check_usd_blender.py"),
                          "--frames", "8", "--set", "resolution=[8,8]", "--out", str(tmp_path)]
                         + (["--blender-python", python] if python else []),
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    lines = res.stdout.splitlines()
    assert "usd_blender.cloth_0.vertices: 64 (simulator: 64)" in lines
    assert [line.split(":")[0] for line in lines if "max_error_m" in line] == [
        "usd_blender.cloth_0.frame_0.max_error_m", "usd_blender.cloth_0.frame_7.max_error_m",
        "usd_blender.back_in.cloth_0.max_error_m"]
    assert lines[-1] == "usd_blender.result: ok"
