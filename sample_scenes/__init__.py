"""Sample scenes: each module has ``build(scene)``, a self-check ``check(scene)``, the frames that
show its point (``SHOWCASE``, rendered by the demo) and the one pictured in the README
(``README_FRAME``, one of them)."""
SCENES = ("fountain", "fireworks", "robot_arm", "jelly_cube", "flag", "cloth_drape", "mesh_pour",
          "rigid_bodies", "dominoes", "t_handle", "rings_peg", "bowl_pile", "arm_throw", "wrecking_ball", "newtons_cradle",
          "banner_ball", "bounce_mark", "droplet", "galaxy", "sand", "bead_coaster", "cloth_pile",
          "rope_swing", "rope_bridge", "roof")
