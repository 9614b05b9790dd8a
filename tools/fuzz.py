"""Random-scene fuzzing of the bake: random objects, roles and property values within their hard
limits, plus absurd values of what Blender owns (gravity, frame rate, scales, frame range).

Each scene is baked, changed at random and baked again. Every bake must either finish with only
finite values in every result, or fail with a message naming an object (or the scene) — and a
failed system must leave its previous bake exactly as it was. No other exception may escape.

    tools/fuzz.sh [COUNT] [FIRST_SEED]     (default 200 scenes from seed 0)

The test suite runs a few scenes of it (tests/blender/test_fuzz.py).
"""
from __future__ import annotations

import math
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

KINDS = ("plane", "cube", "ico_sphere", "monkey", "grid", "empty")
ROLES = ("emitter", "collider", "spring_mesh", "force")  # drawn per object
CHANGED = ROLES + ("rigid_body",)  # (rigid bodies are drawn after the rest: :func:`build_scene`)
VERBOSE = False  # print every failure message (tools/fuzz.sh ... -v)
SKIP = {"enabled", "result", "bake_hash", "seed", "parent", "instance_object", "output",
        "pin_group", "target", "vertex_group"}


def _value(rng: np.random.Generator, prop):
    """A random value of an RNA property within its hard limits (wide ranges log-uniformly)."""
    if prop.type == 'ENUM':
        return str(rng.choice([item.identifier for item in prop.enum_items]))
    if prop.type == 'BOOLEAN':
        return bool(rng.random() < 0.5)
    lo, hi = prop.hard_min, prop.hard_max
    if prop.type == 'INT':
        lo, hi = max(lo, -50), min(hi, 50)
        return int(rng.integers(lo, hi + 1))
    if rng.random() < 0.15:
        return float(rng.choice([lo, hi]))  # the limits themselves
    if lo >= 0.0 and hi / max(lo, 1e-12) > 1e3:
        low = max(lo, 1e-6)
        return float(math.exp(rng.uniform(math.log(low), math.log(hi))))
    if lo < 0.0 < hi and hi - lo > 1e3:
        magnitude = math.exp(rng.uniform(math.log(1e-3), math.log(max(-lo, hi))))
        return float(np.clip(magnitude * rng.choice([-1.0, 1.0]), lo, hi))
    return float(rng.uniform(lo, hi))


def _randomise(rng, group, keep: float = 0.6) -> None:
    """Give some properties of a property group random values (the rest keep their defaults)."""
    for prop in group.bl_rna.properties:
        key = prop.identifier
        if key in SKIP or key == "rna_type" or prop.is_readonly or rng.random() < keep:
            continue
        if prop.type in ('POINTER', 'COLLECTION', 'STRING'):
            continue
        if getattr(prop, "is_array", False):
            continue
        try:
            setattr(group, key, _value(rng, prop))
        except (TypeError, ValueError):  # e.g. an enum item that only some objects offer
            pass
    for key in ("lifetime", "size"):  # mostly a spread a user would pick, sometimes any
        if hasattr(group, f"{key}_random") and rng.random() < 0.7:
            setattr(group, f"{key}_random", getattr(group, key) * float(rng.uniform(0.0, 1.0)))


def _absurd(rng, scene, objects) -> str:
    """Set one absurd value of something Blender owns; returns what it was."""
    choice = int(rng.integers(5))
    if choice == 0:
        scene.gravity = tuple(float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(3, 35))
                              for _ in range(3))
        return "gravity"
    if choice == 1:
        scene.render.fps_base = float(rng.choice([1e-5, 1e5]))
        return "fps"
    if choice == 2 and objects:
        ob = objects[int(rng.integers(len(objects)))]
        ob.scale = tuple(float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-9, 9))
                         for _ in range(3))
        return f"scale of {ob.name}"
    if choice == 3 and objects:
        ob = objects[int(rng.integers(len(objects)))]
        ob.location = tuple(float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(3, 30))
                            for _ in range(3))
        return f"location of {ob.name}"
    scene.physanim.frame_end = scene.physanim.frame_start + int(rng.choice([0, 1, 200_000]))
    return "frame range"


def build_scene(seed: int):
    """A random scene in the current (empty) file; returns its role objects."""
    import bpy

    rng = np.random.default_rng(seed)
    scene = bpy.context.scene
    s = scene.physanim
    s.frame_start = int(rng.integers(-3, 4))
    s.frame_end = s.frame_start + int(rng.integers(0, 4))
    s.substeps = int(rng.integers(1, 4))
    s.integrator = str(rng.choice(["EULER", "SYMPLECTIC_EULER", "MIDPOINT", "RK4", "RK45",
                                   "IMPLICIT"]))
    s.seed = int(rng.integers(1000))
    objects = []
    for i in range(int(rng.integers(1, 4))):
        kind = str(rng.choice(KINDS))
        if kind == "empty":
            ob = bpy.data.objects.new(f"Empty{i}", None)
            scene.collection.objects.link(ob)
        else:
            getattr(bpy.ops.mesh, f"primitive_{kind}_add")()
            ob = bpy.context.object
            ob.name = f"{kind}{i}"
        ob.location = tuple(rng.uniform(-2, 2, 3))
        ob.rotation_euler = tuple(rng.uniform(-math.pi, math.pi, 3))
        if rng.random() < 0.3:
            ob.scale = tuple(rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 3.0, 3))
        roles = [r for r in ROLES if rng.random() < 0.45]
        if not roles:
            roles = ["emitter"]
        if ob.type != 'MESH':
            roles = [r for r in roles if r != "spring_mesh"] or ["emitter"]
        if "spring_mesh" in roles:  # (a spring mesh cannot be a collider too: refused by name)
            roles = [r for r in roles if r != "collider"]
        for role in roles:
            group = getattr(ob.physanim, role)
            group.enabled = True
            _randomise(rng, group)
        objects.append(ob)
    if rng.random() < 0.25:
        _absurd(rng, scene, objects)
    if rng.random() < 0.35:  # a constraint holding one of them (any type, maybe a wrong one)
        held = bpy.data.objects.new("Constraint", None)
        scene.collection.objects.link(held)
        held.location = tuple(rng.uniform(-2, 2, 3))
        c = held.physanim.constraint
        c.enabled = True
        _randomise(rng, c)
        c.object1 = objects[int(rng.integers(len(objects)))]
        if rng.random() < 0.5:
            c.object2 = objects[int(rng.integers(len(objects)))]
        objects.append(held)
    if rng.random() < 0.3:  # slow motion, a speed-up, or the limits (drawn last: the scenes of
        # earlier seeds stay as they were)
        s.time_scale = float(rng.choice([0.01, 0.3, 2.5, 100.0]))
    if rng.random() < 0.4:  # rigid bodies (drawn after the rest, for the same reason)
        for ob in objects:  # (rarely on a spring mesh: the two exclude each other)
            if rng.random() < (0.06 if ob.physanim.spring_mesh.enabled else 0.6):
                _rigid(rng, ob.physanim.rigid_body)
    return rng, objects


def _rigid(rng, group) -> None:
    """A rigid body with random settings, and sometimes random (or absurd) starting motion."""
    group.enabled = True
    _randomise(rng, group)
    for key in ("initial_velocity", "initial_angular_velocity"):
        if rng.random() < 0.3:
            setattr(group, key, tuple(float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-2, 6))
                                      for _ in range(3)))


def _snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()} if root.exists() else {}


def _rigid_keys(ext, scene) -> dict[str, tuple]:
    """Every rigid body's animation as it is now: its rotation mode and each F-curve's keys."""
    compat = sys.modules[f"{ext.__name__}.addon.compat"]
    out = {}
    for ob in scene.objects:
        if not ob.physanim.rigid_body.enabled:
            continue
        curves = []
        for fc in compat.action_fcurves(ob.animation_data):
            co = np.empty(2 * len(fc.keyframe_points))
            fc.keyframe_points.foreach_get("co", co)
            curves.append((fc.data_path, fc.array_index, co.tobytes()))
        out[ob.name] = (ob.rotation_mode, sorted(curves))
    return out


def _check_results(ext, scene) -> None:
    """Every float in every result of the scene is finite."""
    import bpy

    cache = sys.modules[f"{ext.__name__}.core.cache"]
    pc2 = sys.modules[f"{ext.__name__}.core.pc2"]
    for ob in scene.objects:
        res = ob.physanim.emitter.result if ob.physanim.emitter.enabled else None
        if res is not None and res.physanim.result.cache:
            folder = Path(bpy.path.abspath(res.physanim.result.cache))
            for f in folder.glob("*.npz"):
                frame = int(re.findall(r"-?\d+", f.stem)[-1])
                arrays = cache.read_frame(folder, frame)
                for key, a in (arrays or {}).items():
                    if a.dtype.kind == 'f' and not np.isfinite(a).all():
                        raise AssertionError(f'{ob.name}: non-finite "{key}" at frame {frame}')
        if ob.physanim.rigid_body.enabled:
            for data_path, index, co in _rigid_keys(ext, scene).get(ob.name, ("", []))[1]:
                if not np.isfinite(np.frombuffer(co)).all():
                    raise AssertionError(f"{ob.name}: a non-finite key on {data_path}[{index}]")
        mod = ob.modifiers.get("physanim")
        if mod is not None and mod.type == 'MESH_CACHE':
            samples = pc2.read_pc2(bpy.path.abspath(mod.filepath))[0]
            if not np.isfinite(samples).all():
                raise AssertionError(f"{ob.name}: non-finite vertex in its PC2 cache")


def _bake_once(ext, scene, names: set[str]) -> str:
    """Bake; check the outcome. Returns 'finished', 'failed' or 'partial'."""
    import bpy

    root = Path(bpy.path.abspath(scene.physanim.cache_dir))
    before = _snapshot(root)
    keys_before = _rigid_keys(ext, scene)
    try:
        result = bpy.ops.physanim.bake()
    except RuntimeError as exc:
        message = str(exc)
        if VERBOSE:
            print("  ", message.strip())
        named = [n for n in names | {scene.name} if f'"{n}"' in message]
        if not named:
            raise AssertionError(f"a failure that names no object: {message}") from exc
        after = _snapshot(root)
        if "the rest baked" not in message:
            if after != before:
                changed = sorted(k for k in before.keys() | after.keys()
                                 if before.get(k) != after.get(k))
                raise AssertionError(f"a failed bake changed the previous one ({len(changed)} "
                                     f"files, e.g. {changed[:3]}): {message}") from exc
            if _rigid_keys(ext, scene) != keys_before:
                raise AssertionError(f"a failed bake changed the rigid bodies' keys: {message}") \
                    from exc
            _check_results(ext, scene)
            return "failed"
        paths = sys.modules[f"{ext.__name__}.addon.cache_paths"]
        kept = re.search(r"not baked \(previous bake kept\): (.*); the rest baked", message)[1]
        failed = [(name, True) for name in re.findall(r'spring mesh "([^"]+)"', kept)]
        for group in re.findall(r"particles \(emitters? (.*?)\)(?:,|$)", kept):
            failed += [(name, False) for name in re.findall(r'"([^"]+)"', group)]
        if "rigid bodies (" in kept and _rigid_keys(ext, scene) != keys_before:
            raise AssertionError(f"the failed rigid bodies lost their previous keys: {message}") \
                from exc
        for name, mesh in failed:
            folder = paths.safe_name(name)
            for key in before:
                parts = key.split("/")
                if (folder in parts and ("spring_meshes" in parts) == mesh
                        and before[key] != after.get(key)):
                    raise AssertionError(f'the failed "{name}" lost its previous bake') from exc
        _check_results(ext, scene)
        return "partial"
    if result != {'FINISHED'}:
        raise AssertionError(f"bake returned {result} without an error report")
    _check_results(ext, scene)
    return "finished"


def run_scene(ext, seed: int, folder: Path) -> list[str]:
    """Build scene ``seed``, bake it, change it at random, bake again. Returns both outcomes."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    rng, objects = build_scene(seed)
    names = {o.name for o in objects}
    bpy.ops.wm.save_as_mainfile(filepath=str(folder / f"fuzz_{seed}.blend"))
    scene = bpy.context.scene
    outcomes = [_bake_once(ext, scene, names)]
    for ob in objects:  # a change, as a user would make between bakes
        for role in CHANGED:
            group = getattr(ob.physanim, role)
            if group.enabled and rng.random() < 0.5:
                _randomise(rng, group, keep=0.8)
    if rng.random() < 0.3:
        _absurd(rng, scene, objects)
    outcomes.append(_bake_once(ext, scene, names))
    return outcomes


def main(argv: list[str]) -> int:
    import tempfile

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tools import blender_env  # before bpy: it keeps Blender's user files in a temp dir

    import bpy  # noqa: F401  (loads Blender; addon_utils needs it)

    os.environ.setdefault("PHYSANIM_CHECKPOINT_SECONDS", "0")  # checkpoints are restored too
    global VERBOSE
    VERBOSE = "-v" in argv
    argv = [a for a in argv if a != "-v"]
    count = int(argv[0]) if argv else 200
    first = int(argv[1]) if len(argv) > 1 else 0
    ext = blender_env.enable_extension()
    tally: dict[str, int] = {}
    problems = []
    started = time.perf_counter()
    try:
        with tempfile.TemporaryDirectory(prefix="physanim_fuzz_") as tmp:
            for seed in range(first, first + count):
                t = time.perf_counter()
                try:
                    outcomes = run_scene(ext, seed, Path(tmp))
                except Exception as exc:  # the fuzzer reports every escape
                    problems.append((seed, f"{type(exc).__name__}: {exc}"))
                    outcomes = ["PROBLEM"]
                for o in outcomes:
                    tally[o] = tally.get(o, 0) + 1
                print(f"scene {seed}: {', '.join(outcomes)} ({time.perf_counter() - t:.1f} s)",
                      flush=True)
    finally:
        blender_env.disable_extension()
    print(f"{count} scenes, {sum(tally.values())} bakes in {time.perf_counter() - started:.0f} s: "
          + ", ".join(f"{k} {v}" for k, v in sorted(tally.items())))
    for seed, problem in problems:
        print(f"PROBLEM in scene {seed}: {problem}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
