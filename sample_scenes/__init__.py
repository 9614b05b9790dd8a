"""Sample scenes: each module has ``NAME``, ``build(scene)`` and a self-check ``check(scene)``."""
SCENES = ("fountain", "fireworks", "robot_arm", "jelly_cube", "flag", "cloth_drape", "mesh_pour")
