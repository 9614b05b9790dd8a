"""What a render farm needs from a shot, behind the ``check``, ``render``, ``wedge`` and ``sheet``
commands of ``blender -c physanim`` (see :mod:`.cli` and ``farm/`` for the job templates):

- :func:`bake_state` / :func:`farm_problems`: what is not baked, outdated, missing on disk, held
  at an absolute path, or plays only where the extension is installed;
- :func:`parse_frames` and :func:`render_frames`: render a list of frames, a line each;
- wedges: :func:`wedge_combinations` expands a spec such as
  ``"Fountain:physanim.emitter.seed=1,2,3;@scene:physanim.substeps=2,4"`` into every combination
  (the last property varies fastest), :func:`apply_wedge` sets one, and :func:`contact_sheet`
  renders one frame of each wedge's file into one picture.
"""
from __future__ import annotations

import ast
import itertools
import json
import math
import os
import re
from collections.abc import Callable

import bpy
import numpy as np

from ..core.cache import read_meta
from . import inputs_hash, native_points
from .roles import gather

SCENE_TARGET = "@scene"


# --- bake state ----------------------------------------------------------------------------------

def bake_state(scene) -> tuple[object, list[str], list[str]]:
    """(roles, missing, outdated): the emitters, spring meshes and rigid bodies with no bake,
    and those whose bake no longer matches the scene (inputs hash)."""
    from . import springs

    roles = gather(scene)
    missing, outdated = [], []
    for ob in roles.emitters:
        res = ob.physanim.emitter.result
        if res is None or not res.physanim.result.cache:
            missing.append(ob.name)
        elif res.physanim.result.hash != inputs_hash.emitter_hash(scene, ob, roles):
            outdated.append(ob.name)
    for ob in roles.spring_meshes:
        if springs.cache_modifier(ob) is None:
            missing.append(ob.name)
        elif ob.physanim.spring_mesh.bake_hash != inputs_hash.inputs_hash(
                scene, ob, "spring_mesh", roles):
            outdated.append(ob.name)
    if roles.rigid_bodies:
        current = inputs_hash.rigid_hash(scene, roles.rigid_bodies, roles)
        for ob in roles.rigid_bodies:
            baked = ob.physanim.rigid_body.bake_hash
            (missing if not baked else outdated if baked != current else []).append(ob.name)
    for ob in roles.followers:
        baked = ob.physanim.follow.bake_hash
        if not baked:
            missing.append(ob.name)
        elif baked != inputs_hash.follow_hash(scene, ob, roles):
            outdated.append(ob.name)
    return roles, missing, outdated


def farm_problems(scene, extension_on_farm: bool = False) -> list[str]:
    """Everything a render of ``scene`` on another machine would miss, one line each (empty:
    nothing). ``extension_on_farm``: the farm has PhysAnim installed, so results that need it
    are fine."""
    from . import springs

    roles, missing, outdated = bake_state(scene)
    problems = [f'"{name}" is not baked' for name in missing]
    problems += [f'"{name}": the bake is outdated (the scene changed since)' for name in outdated]

    def path_problem(owner: str, what: str, path: str, expect_file: bool) -> None:
        if not path:
            return
        if not path.startswith("//"):
            problems.append(f'"{owner}": {what} "{path}" is an absolute path — a farm node sees '
                            "it only if it has the same path; use a '//'-relative one")
        full = bpy.path.abspath(path)
        exists = os.path.isfile(full) if expect_file else os.path.isdir(full)
        if not exists:
            problems.append(f'"{owner}": {what} "{path}" is not on disk ({full})')

    for ob in roles.emitters:
        res = ob.physanim.emitter.result
        if res is None or not res.physanim.result.cache:
            continue
        p = ob.physanim.emitter
        path_problem(ob.name, "particle cache", res.physanim.result.cache, expect_file=False)
        cache = res.modifiers.get(native_points.CACHE_MODIFIER)
        if res.type == 'POINTCLOUD' and cache is not None and cache.cache_file is not None:
            path_problem(ob.name, "USD points", cache.cache_file.filepath, expect_file=True)
            folder = os.path.dirname(bpy.path.abspath(cache.cache_file.filepath))
            meta = read_meta(os.path.dirname(folder)) or {}
            want = meta.get("frame_end", 0) - meta.get("frame_start", 1) + 1
            have = len(os.listdir(folder)) if os.path.isdir(folder) else 0
            if meta and have != want:
                problems.append(f'"{ob.name}": {have} USD point files for {want} baked frames '
                                f"in {folder}")
        elif res.type == 'MESH' and p.output == 'POINTS' and not extension_on_farm:
            problems.append(f'"{ob.name}": Output "Points (Extension)" renders only where '
                            "PhysAnim is installed — choose Output: Points and re-bake, or pass "
                            "--extension-on-farm")
    for ob in roles.spring_meshes:
        modifier = springs.cache_modifier(ob)
        if modifier is not None:
            path_problem(ob.name, "mesh cache", modifier.filepath, expect_file=True)
    return problems


# --- frames and rendering ------------------------------------------------------------------------

def parse_frames(text: str) -> list[int]:
    """Frames of a range expression: ``"7"``, ``"1-250"``, ``"1-9:2"`` (a step), or several
    joined by commas (``"1,5,10-12"``), in order, without repeats.

    Raises:
        ValueError: anything else, with the offending part.
    """
    frames: list[int] = []
    for part in text.split(","):
        m = re.fullmatch(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*(?::\s*(\d+)\s*)?)?", part)
        if not m:
            raise ValueError(f'"{part.strip()}" is not a frame, A-B or A-B:STEP')
        first = int(m[1])
        last = int(m[2]) if m[2] is not None else first
        step = int(m[3]) if m[3] else 1
        if last < first or step < 1:
            raise ValueError(f'"{part.strip()}" is an empty range')
        frames += [f for f in range(first, last + 1, step) if f not in frames]
    return frames


def render_frames(scene, frames: list[int], output: str, log: Callable[[str], None]) -> None:
    """Render ``frames`` of ``scene`` to ``output`` (Blender's '#' frame-number pattern; a
    '//'-relative path resolves against the .blend), one log line per frame."""
    render = scene.render
    for frame in frames:
        scene.frame_set(frame)
        render.filepath = _frame_path(output, frame)
        bpy.ops.render.render(write_still=True, scene=scene.name)
        log(f"rendered frame {frame}: {bpy.path.abspath(render.frame_path(frame=frame))}")


def _frame_path(pattern: str, frame: int) -> str:
    """``pattern`` with its last run of '#' replaced by the zero-padded frame (Blender's rule);
    without one, the frame is appended with four digits."""
    runs = list(re.finditer(r"#+", pattern))
    if not runs:
        return f"{pattern}{frame:04d}"
    run = runs[-1]
    return pattern[:run.start()] + f"{frame:0{len(run.group())}d}" + pattern[run.end():]


# --- wedges --------------------------------------------------------------------------------------

def wedge_combinations(spec: str) -> list[list[tuple[str, str, object]]]:
    """Every combination of a wedge spec: ``TARGET:PATH=V1,V2,...`` items joined by ';'.

    TARGET is an object name or ``@scene``; PATH a property path from it
    (``physanim.emitter.seed``); values are numbers, ``True``/``False`` or names (enum items).
    Returns lists of (target, path, value), the last item varying fastest.

    Raises:
        ValueError: a malformed item, naming it.
    """
    axes = []
    for item in filter(None, (i.strip() for i in spec.split(";"))):
        m = re.fullmatch(r"(.+?):([A-Za-z_][\w.]*)\s*=\s*(.+)", item)
        if not m:
            raise ValueError(f'wedge item "{item}" must look like Object:path.to.prop=1,2,3')
        values = [_value(v.strip()) for v in m[3].split(",") if v.strip()]
        if not values:
            raise ValueError(f'wedge item "{item}" has no values')
        axes.append([(m[1].strip(), m[2], v) for v in values])
    if not axes:
        raise ValueError("the wedge spec is empty")
    return [list(combo) for combo in itertools.product(*axes)]


def _value(text: str):
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text  # an enum item or another name


def apply_wedge(scene, combo: list[tuple[str, str, object]]) -> None:
    """Set each (target, path, value) of one combination.

    Raises:
        ValueError: a missing object or property, a keyframed property (its animation would
            override the wedge) or a value the property refuses, naming the item.
    """
    for target, path, value in combo:
        owner = scene if target == SCENE_TARGET else bpy.data.objects.get(target)
        if owner is None:
            raise ValueError(f'wedge: no object named "{target}"')
        head, _, name = path.rpartition(".")
        try:
            holder = owner.path_resolve(head) if head else owner
        except ValueError:
            raise ValueError(f'wedge: "{target}" has no property "{head}"') from None
        if not hasattr(holder, name):
            raise ValueError(f'wedge: "{target}" has no property "{path}"')
        anim = getattr(owner, "animation_data", None)
        if anim is not None and anim.action is not None and any(
                fc.data_path == path for fc in _fcurves(anim)):
            raise ValueError(f'wedge: "{target}" {path} is keyframed — its animation would '
                             "override the wedge value")
        try:
            setattr(holder, name, value)
        except (TypeError, ValueError, AttributeError) as exc:
            raise ValueError(f'wedge: "{target}" {path} = {value!r}: {exc}') from None


def _fcurves(anim):
    from . import compat

    return compat.action_fcurves(anim)


def wedge_label(combo) -> str:
    return ", ".join(f"{t}:{p}={v}" for t, p, v in combo)


def wedge_file(blend: str, index: int) -> str:
    stem, ext = os.path.splitext(blend)
    return f"{stem}_wedge_{index:03d}{ext}"


def contact_sheet(files: list[str], frame: int, output: str, labels: list[str],
                  log: Callable[[str], None], scale: int = 50) -> str:
    """Render ``frame`` of each file (at ``scale`` percent) and tile the pictures, row by row,
    into one PNG at ``output``; a JSON beside it lists each tile's file and label. Returns the
    PNG's path."""
    tiles = []
    folder = os.path.dirname(os.path.abspath(output))
    os.makedirs(folder, exist_ok=True)
    for index, path in enumerate(files):
        bpy.ops.wm.open_mainfile(filepath=path)
        scene = bpy.context.scene
        scene.render.resolution_percentage = scale
        scene.render.image_settings.file_format = 'PNG'
        scene.render.image_settings.color_mode = 'RGBA'
        tile = os.path.join(folder, f".sheet_tile_{index:03d}.png")
        scene.frame_set(frame)
        scene.render.filepath = tile
        bpy.ops.render.render(write_still=True)
        tiles.append(_pixels(tile))
        os.remove(tile)
        log(f"sheet: wedge {index + 1} rendered ({labels[index]})")
    height = max(t.shape[0] for t in tiles)
    width = max(t.shape[1] for t in tiles)
    columns = math.ceil(math.sqrt(len(tiles)))
    rows = math.ceil(len(tiles) / columns)
    sheet = np.zeros((rows * height, columns * width, 4), np.float32)
    for index, tile in enumerate(tiles):
        row, column = divmod(index, columns)
        top = (rows - 1 - row) * height  # image rows start at the bottom: row 0 on top
        sheet[top:top + tile.shape[0], column * width:column * width + tile.shape[1]] = tile
    image = bpy.data.images.new("physanim_sheet", sheet.shape[1], sheet.shape[0], alpha=True)
    image.pixels.foreach_set(sheet.ravel())
    image.filepath_raw = output
    image.file_format = 'PNG'
    image.save()
    bpy.data.images.remove(image)
    with open(os.path.splitext(output)[0] + ".json", "w", encoding="utf-8") as handle:
        json.dump({"frame": frame, "columns": columns, "rows": rows,
                   "tiles": [{"wedge": i + 1, "file": f, "values": labels[i]}
                             for i, f in enumerate(files)]}, handle, indent=1)
    return output


def _pixels(path: str) -> np.ndarray:
    image = bpy.data.images.load(path)
    width, height = image.size
    pixels = np.empty(width * height * 4, np.float32)
    image.pixels.foreach_get(pixels)
    bpy.data.images.remove(image)
    return pixels.reshape(height, width, 4)
