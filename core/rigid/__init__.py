"""Rigid bodies (Witkin & Baraff's x, R, P, L): mass properties from shapes and meshes, a
builder -> frozen model -> state, free motion with the angular momentum held, contacts found
once per frame (broad phase, narrow phase by shape pair) and a soft-step contact solver."""
