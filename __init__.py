"""PhysAnim: physically based animation for Blender.

The package root is both the Blender extension (``register``/``unregister``) and the parent of the
Blender-free simulation library ``core``. Importing this module must not import ``bpy`` so that
``core`` stays usable from plain Python; the Blender layer is imported lazily in ``register``.
"""


def register() -> None:
    from . import addon

    addon.register()


def unregister() -> None:
    from . import addon

    addon.unregister()
