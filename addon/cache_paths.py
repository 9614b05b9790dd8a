"""Where bakes live on disk: one folder per scene and object, '//'-relative to the .blend."""
from __future__ import annotations

import hashlib
import os
import re

import bpy

from ..core.errors import PhysanimError


def safe_name(name: str) -> str:
    """A file-system safe, readable and unique folder name for an object or scene name: the
    readable part may collide ("Fire 1", "Fire_1"), so a hash of the exact name follows it."""
    readable = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "object"
    return f"{readable[:48]}-{hashlib.sha1(name.encode('utf-8')).hexdigest()[:8]}"


def cache_root(scene) -> str:
    """Absolute cache folder of a scene; errors when a '//' path has no saved .blend to anchor it."""
    raw = scene.physanim.cache_dir.strip()
    if not raw:
        raise PhysanimError("the cache folder is empty — set Scene > PhysAnim > Cache",
                            obj=scene.name, kind="scene")
    if raw.startswith("//") and not bpy.data.filepath:
        raise PhysanimError(f'the cache folder "{raw}" is relative to the .blend file, which is not '
                            "saved yet — save the file first or choose an absolute cache folder",
                            obj=scene.name, kind="scene")
    return os.path.normpath(bpy.path.abspath(raw))


def emitter_cache_dir(scene, ob) -> str:
    return os.path.join(cache_root(scene), safe_name(scene.name), safe_name(ob.name))


def spring_cache_dir(scene, ob) -> str:
    """Spring meshes bake into their own sub-folder: an object may also be an emitter."""
    return os.path.join(cache_root(scene), safe_name(scene.name), "spring_meshes",
                        safe_name(ob.name))


def rigid_cache_dir(scene) -> str:
    """Every rigid body of a scene bakes into one folder: they are one system."""
    return os.path.join(cache_root(scene), safe_name(scene.name), "rigid_bodies")


def relative_path(path: str) -> str:
    """'//'-relative path with forward slashes when the .blend is saved (else absolute)."""
    if bpy.data.filepath:
        try:
            return bpy.path.relpath(path).replace("\\", "/")
        except ValueError:  # other drive on Windows
            pass
    return path.replace("\\", "/")
