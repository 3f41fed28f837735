"""Checkpoints: a simulator's scene, settings and state in one ``.npz`` file.

The scene is stored as plain arrays plus a JSON description and rebuilt through the same
validating ``Scene`` methods a script uses, so a damaged or hand-edited file is refused
with a ``SceneError`` naming what is wrong. Each scene feature (``features.FEATURES``) is
stored as the arguments of its Scene method that rebuild it (its ``saved``): NumPy
arrays as arrays named ``feature_<name>_<argument>``, the rest as JSON. Files of format
version 1 (features under keys of their own) are read too. Files are written to a
temporary name, flushed and renamed: a crash mid-write never leaves a corrupt checkpoint
under the real name.
"""
import json
import os
import zipfile

import numpy as np

from .. import runtime
from ..errors import SceneError
from ..scene.builders import Cloth, MeshCloth, Rope
from ..features import FEATURES
from ..scene.scene import KIND_CODE, SPRING_KINDS, Scene
from ..geometry.shapes import COMMON, SHAPE_NAMES, shape_of

FORMAT = "tcloth-checkpoint"
VERSION = 2
READS = (1, 2)


def _plain(value):
    """JSON-able: arrays as lists, dicts entry by entry (None stays None)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value.tolist() if isinstance(value, np.ndarray) else value


def _save_features(scene, desc, arrays):
    """Each present feature's method arguments into desc["features"] and arrays."""
    desc["features"] = {}
    for feature in FEATURES:
        value = getattr(scene, feature.name)
        if value is None:
            continue
        args = feature.saved(value)
        stored = sorted(k for k, v in args.items() if isinstance(v, np.ndarray))
        for key in stored:
            arrays[f"feature_{feature.name}_{key}"] = args[key]
        desc["features"][feature.name] = {
            "args": {k: _plain(v) for k, v in args.items() if k not in stored},
            "arrays": stored}


def _load_features(scene, desc, arrays):
    """Call each stored feature's Scene method with its stored arguments."""
    known = {feature.name: feature for feature in FEATURES}
    unknown = sorted(set(desc["features"]) - set(known))
    if unknown:
        raise SceneError(f"checkpoint holds a scene feature this tcloth does not know: "
                         f"{unknown[0]!r} (known: {', '.join(known)})")
    for feature in FEATURES:
        entry = desc["features"].get(feature.name)
        if entry is None:
            continue
        args = dict(entry["args"])
        args.update({key: arrays[f"feature_{feature.name}_{key}"] for key in entry["arrays"]})
        try:
            getattr(scene, feature.method)(**args)
        except TypeError as e:
            raise SceneError(f"checkpoint's {feature.name} arguments do not fit "
                             f"Scene.{feature.method}: {e}") from None


def _from_version_1(desc, files):
    """Version 1's description and files in version 2's layout: its wind, attraction,
    strain limit and self-collision, stored under keys of their own, move under
    "features" as their Scene methods' arguments."""
    features = {}
    wind = desc.pop("wind", None)
    if wind is not None:
        gust = {k: wind.pop(k) for k in ("amplitude", "frequency", "phase")}
        features["wind"] = {"args": {**wind, "gust": gust}, "arrays": []}
    attraction = desc.pop("attraction", None)
    if attraction is not None:
        features["attraction"] = {"args": dict(zip(("G", "softening"), attraction)),
                                  "arrays": []}
    limit = desc.pop("strain_limit", None)
    if limit is not None:
        if "scene_strain_springs" in files:
            files["scene_feature_strain_limit_springs"] = files.pop("scene_strain_springs")
        features["strain_limit"] = {"args": limit, "arrays": ["springs"]}
    settings = desc.pop("self_collision", None)
    if settings is not None:
        features["self_collision"] = {"args": settings, "arrays": []}
    desc["features"] = features


def scene_to_arrays(scene):
    """(JSON-able description, dict of arrays) of a Scene."""
    sp = scene.springs
    arrays = {"positions": scene.positions, "velocities": scene.velocities,
              "masses": scene.masses, "pinned": scene.pinned, "spring_pairs": sp["pairs"],
              "spring_stiffness": sp["stiffness"], "spring_damping": sp["damping"],
              "spring_rest": sp["rest_length"], "spring_kind": sp["kind"]}
    desc = {"gravity": scene.gravity.tolist(), "air_drag": scene.air_drag,
            "air_damping": scene.air_damping, "cloths": [], "ropes": [], "colliders": []}
    for k, c in enumerate(scene.cloths):
        if c.is_grid:
            desc["cloths"].append({"offset": int(c.offset), "resolution": list(c.resolution),
                                   "spacing": list(c.spacing), "params": c.params,
                                   "plane": c.plane, "stencil": c.stencil})
        else:
            desc["cloths"].append({"mesh": True, "offset": int(c.offset),
                                   "count": len(c.particles), "params": c.params})
            arrays[f"cloth{k}_triangles"] = c.triangles - c.offset
            if c.uv is not None:
                arrays[f"cloth{k}_uv"] = c.uv
        for family, ids in c.springs.items():
            arrays[f"cloth{k}_{family}"] = ids
    for k, r in enumerate(scene.ropes):
        arrays[f"rope{k}_particles"] = r.particles
        arrays[f"rope{k}_springs"] = r.springs
    desc["ropes"] = len(scene.ropes)
    for k, c in enumerate(scene.colliders):
        desc["colliders"].append(_plain(c) if c["kind"] != "mesh" else _mesh_to_arrays(
            k, c, arrays))
    desc["welds"] = [w["distance"] for w in scene.welds]
    for k, w in enumerate(scene.welds):
        arrays[f"weld{k}_pairs"] = w["pairs"]
    _save_features(scene, desc, arrays)
    return desc, arrays


def _mesh_to_arrays(k, c, arrays):
    """A mesh collider's description, its mesh (and deform frames) into ``arrays``: by
    content, not by the path it came from."""
    if callable(c["deform"]):
        raise SceneError(f"collider {k} (a mesh) deforms by a callable, which a checkpoint "
                         "cannot store: give deform as a (frames, V, 3) array to save it")
    arrays[f"collider{k}_vertices"] = c["vertices"]
    arrays[f"collider{k}_faces"] = c["faces"]
    if c["deform"] is not None:
        arrays[f"collider{k}_deform"] = c["deform"] * c["scale"]
    keep = ("kind", "center", "rotation", "velocity", "spin", "keyframes", "deform_fps",
            "sdf", *(name for name, _ in COMMON if name != "velocity"))
    return {key: _plain(c[key]) if key != "keyframes" or c[key] is None
            else [[t, p.tolist(), r.tolist()] for t, p, r in c[key]] for key in keep}


def _mesh_from_arrays(scene, k, c, arrays):
    """``_mesh_to_arrays`` read back into ``scene``."""
    moving = c["keyframes"] is not None or f"collider{k}_deform" in arrays
    scene.add_mesh_collider(
        (arrays[f"collider{k}_vertices"], arrays[f"collider{k}_faces"]),
        position=c["center"], rotation=c["rotation"],
        velocity=None if moving else c["velocity"],
        angular_velocity=None if moving else c["spin"], keyframes=c["keyframes"],
        deform=arrays.get(f"collider{k}_deform"), deform_fps=c["deform_fps"],
        sdf=c.get("sdf", "auto"),       # absent before mesh fields
        **{name: c[name] for name, _ in COMMON if name != "velocity"})


def _runs(kinds):
    """Start/stop of runs of equal spring kinds, in order."""
    if len(kinds) == 0:
        return []
    cuts = np.flatnonzero(np.diff(kinds)) + 1
    starts = np.concatenate([[0], cuts])
    stops = np.concatenate([cuts, [len(kinds)]])
    return list(zip(starts, stops))


def scene_from_arrays(desc, arrays):
    """Rebuild a Scene with the validating Scene methods."""
    scene = Scene(gravity=desc["gravity"], air_drag=desc["air_drag"],
                  air_damping=desc.get("air_damping", 0.0))     # absent before air_damping
    scene.add_particles(arrays["positions"], mass=arrays["masses"],
                        velocities=arrays["velocities"], pinned=arrays["pinned"].astype(bool))
    kinds = arrays["spring_kind"]
    if len(kinds) and (kinds.min() < 0 or kinds.max() >= len(SPRING_KINDS)):
        raise SceneError(f"checkpoint field spring_kind holds codes outside "
                         f"0..{len(SPRING_KINDS) - 1}")
    for a, b in _runs(kinds):
        scene.add_springs(arrays["spring_pairs"][a:b], arrays["spring_stiffness"][a:b],
                          arrays["spring_damping"][a:b], arrays["spring_rest"][a:b],
                          kind=SPRING_KINDS[kinds[a]])
    for k, c in enumerate(desc["cloths"]):
        params = {f: (tuple(p) if p is not None else None) for f, p in c["params"].items()}
        if c.get("mesh"):
            cloth = MeshCloth(c["offset"], c["count"], arrays[f"cloth{k}_triangles"], params,
                              arrays.get(f"cloth{k}_uv"))     # absent: no texture coordinates
        else:
            cloth = Cloth(c["offset"], tuple(c["resolution"]), tuple(c["spacing"]), params,
                          c["plane"], c.get("stencil", True))
        if cloth.particles.max() >= scene.num_particles:
            raise SceneError(f"checkpoint cloth {k} refers to particles beyond the "
                             f"{scene.num_particles} stored")
        for family in ("structural", "shear", "flexion"):
            ids = arrays[f"cloth{k}_{family}"]
            if len(ids) and (ids.max() >= scene.num_springs or
                             np.any(scene.springs["kind"][ids] != KIND_CODE[family])):
                raise SceneError(f"checkpoint cloth {k}'s {family} springs do not match "
                                 "the stored spring list")
            cloth.springs[family] = ids
        scene.cloths.append(cloth)
    for k in range(desc["ropes"]):
        scene.ropes.append(Rope(arrays[f"rope{k}_particles"], arrays[f"rope{k}_springs"]))
    seams = {tuple(p) for p in scene.springs["pairs"][scene.springs["kind"] ==
                                                      KIND_CODE["seam"]].tolist()}
    for k, distance in enumerate(desc.get("welds", [])):      # absent before welds
        pairs = np.asarray(arrays[f"weld{k}_pairs"], dtype=np.int64).reshape(-1, 2)
        if any(tuple(p) not in seams for p in pairs.tolist()):
            raise SceneError(f"checkpoint weld {k} joins particles no stored seam joins")
        scene.welds.append({"pairs": pairs, "distance": distance})
    for k, c in enumerate(desc["colliders"]):
        kind = c.get("kind")
        if kind not in SHAPE_NAMES:
            raise SceneError(f"checkpoint holds a collider of unknown kind {kind!r}")
        try:
            if kind == "mesh":
                _mesh_from_arrays(scene, k, c, arrays)
                continue
            getattr(scene, f"add_{kind}")(
                **{p.name: c[p.stored] for p in shape_of(c).parameters},
                **{name: c[name] for name, _ in COMMON})
        except KeyError as e:
            raise SceneError(f"checkpoint's {kind} collider lacks its {e.args[0]!r}") from None
    _load_features(scene, desc, arrays)
    return scene


def save(sim, path):
    """Write ``sim`` to ``path`` (.npz) atomically."""
    desc, arrays = scene_to_arrays(sim.scene)
    meta = {"format": FORMAT, "version": VERSION, "scene": desc,
            "integrator": sim.integrator_name, "dt": sim.dt, "options": dict(sim.integrator.options),
            "settings": sim.settings, "precision": sim.precision,
            "num_steps": sim.num_steps, "time_base": sim._time_base,
            "step_base": sim._step_base, "grabbed": _plain(sim.grabbed),
            "forces_valid": sim.integrator.holds_forces(sim.state),
            "splits": sim._splitter.saved(), "torn": sim.torn().tolist()}
    state = sim.state
    payload = {f"scene_{k}": v for k, v in arrays.items()}
    payload.update(meta=np.array(json.dumps(meta)), state_x=state.x.to_numpy(),
                   state_v=state.v.to_numpy(), state_f=state.f.to_numpy())
    if sim._welds is not None:                  # which welded seams' pairs have met
        payload["state_welded"] = sim._welds.welded.to_numpy()
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise SceneError(f"cannot save checkpoint: folder {folder!r} does not exist")
    atomic_write(path, lambda f: np.savez(f, **payload))


def atomic_write(path, write, mode="wb"):
    """``write(f)`` into ``PATH.partial``, flushed to disk, then renamed to ``path``: a
    reader sees the old file or the whole new one, never part of it (the partial file is
    removed if ``write`` fails)."""
    path = os.fspath(path)
    tmp = path + ".partial"
    try:
        with open(tmp, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def read(path):
    """(meta dict, scene arrays, state arrays) from a checkpoint, checked."""
    if not os.path.isfile(path):
        raise SceneError(f"checkpoint {path!r} does not exist")
    if not zipfile.is_zipfile(path):
        # np.load would try the bytes as a pickle, and say so
        raise SceneError(f"checkpoint {path!r} is not a readable .npz file: not a zip "
                         "archive (truncated or damaged, or not written by Simulator.save)")
    try:
        with np.load(path, allow_pickle=False) as data:
            files = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise SceneError(f"checkpoint {path!r} is not a readable .npz file "
                         f"(truncated or damaged?): {e}") from None
    if "meta" not in files:
        raise SceneError(f"checkpoint {path!r} lacks its 'meta' field: not a tcloth checkpoint")
    try:
        meta = json.loads(str(files["meta"]))
    except json.JSONDecodeError as e:
        raise SceneError(f"checkpoint {path!r}: its 'meta' field is not valid JSON: {e}") from None
    if meta.get("format") != FORMAT:
        raise SceneError(f"checkpoint {path!r} is not a tcloth checkpoint "
                         f"(format {meta.get('format')!r})")
    if meta.get("version") not in READS:
        raise SceneError(f"checkpoint {path!r} has format version {meta.get('version')!r}; "
                         f"this tcloth reads versions {', '.join(map(str, READS))}")
    needed = ["state_x", "state_v", "state_f", "scene_positions", "scene_velocities",
              "scene_masses", "scene_pinned", "scene_spring_pairs", "scene_spring_stiffness",
              "scene_spring_damping", "scene_spring_rest", "scene_spring_kind"]
    desc = meta["scene"]
    if meta["version"] == 1:
        _from_version_1(desc, files)
    needed += [f"scene_cloth{k}_{f}" for k in range(len(desc["cloths"]))
               for f in ("structural", "shear", "flexion")]
    needed += [f"scene_rope{k}_{f}" for k in range(desc["ropes"]) for f in ("particles", "springs")]
    needed += [f"scene_feature_{name}_{key}" for name, entry in desc["features"].items()
               for key in entry["arrays"]]
    missing = [k for k in needed if k not in files]
    if missing:
        raise SceneError(f"checkpoint {path!r} lacks field {missing[0]!r}")
    n = len(files["scene_positions"])
    for key in ("state_x", "state_v", "state_f"):
        if files[key].shape != (n, 3):
            raise SceneError(f"checkpoint {path!r}: field {key!r} has shape {files[key].shape}, "
                             f"expected ({n}, 3) for its {n} particles")
    scene_arrays = {k[len("scene_"):]: v for k, v in files.items() if k.startswith("scene_")}
    return meta, scene_arrays, files


def load(simulator_class, path):
    """A ``simulator_class`` (``Simulator``) continuing exactly where the one saved at
    ``path`` stopped (``Simulator.load``)."""
    meta, scene_arrays, files = read(path)
    runtime.ensure_init()
    if meta["precision"] != runtime.precision():
        raise SceneError(f"checkpoint {path!r} was saved in precision "
                         f"{meta['precision']!r}; call tcloth.init(precision="
                         f"{meta['precision']!r}) before loading it")
    scene = scene_from_arrays(meta["scene"], scene_arrays)
    sim = simulator_class(scene, meta["integrator"], dt=meta["dt"], **meta["settings"],
                          **meta["options"])
    if meta.get("torn"):
        sim._tearing.restore(meta["torn"])
        sim.integrator.parameters_changed()
    npr = runtime.numpy_real()
    state = sim.state
    state.x.from_numpy(files["state_x"].astype(npr))
    state.v.from_numpy(files["state_v"].astype(npr))
    state.f.from_numpy(files["state_f"].astype(npr))
    if sim._welds is not None and "state_welded" in files:
        sim._welds.welded.from_numpy(files["state_welded"])
    if meta["forces_valid"]:
        sim.integrator.adopt_forces(state)
    if sim.contact is not None:
        sim.contact.refresh(state.x)
    sim.num_steps = int(meta["num_steps"])
    sim._time_base = float(meta.get("time_base", 0.0))
    sim._step_base = int(meta.get("step_base", 0))
    sim._splitter.restore(meta.get("splits"))
    state.t = sim.time
    if meta.get("grabbed"):
        held = meta["grabbed"]
        sim.grab(held["particle"], held["target"], held["stiffness"], held["damping"])
    sim._rebase()
    return sim
