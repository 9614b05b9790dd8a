"""How particles render (the emitter's Render As), each a native Geometry Nodes setup on the
result's ``physanim_instances`` modifier, applied at once when the setting changes (no re-bake):

- **Objects**: any object instanced on every point (default: a sphere showing the colours), scaled
  by ``size`` and, with the bake's Stretch, shaped by velocity (:mod:`.instancing`).
- **Billboards**: camera-facing squares with an image (the emitter's Sprite; default a soft round
  dot), coloured and faded by each particle's ``color``. The scene's active camera is looked up
  in the node tree, so they face whichever camera renders.
- **Glowing Points**: camera-facing soft discs that only emit light, in the particle's colour,
  with a strength, and are otherwise transparent: overlapping glows add up (sparks, fireworks).
  In Cycles each glow a ray passes is one transparent bounce: where more overlap than Light
  Paths > Transparent bounces allows (8 by default), the rest turn black — raise it for dense
  bursts.
- **Blobs**: one smooth surface around all points, as metaballs: Points to Volume (radius =
  ``size`` x Blob Size) then Volume to Mesh, coloured by the nearest particle's ``color``.
- **Streaks**: the instanced object stretched along its velocity over the Streak Time — the path
  each particle covers in that time — computed from ``velocity`` at render time.

Everything here is Blender's own data (node groups, materials, an icosphere): it renders where
the extension is not installed.
"""
from __future__ import annotations

import bpy

from . import compat, instancing

RENDER_ITEMS = [
    ('OBJECT', "Objects", "Instances of an object on every particle (default: a sphere)"),
    ('BILLBOARD', "Billboards", "Camera-facing squares with an image (default: a soft dot)"),
    ('GLOW', "Glowing Points", "Camera-facing soft glows of the particle colour, otherwise "
     "transparent: overlapping glows add up (sparks, fireworks)"),
    ('BLOBS', "Blobs", "One smooth surface around the particles, like metaballs (liquids)"),
    ('STREAKS', "Streaks", "The instance stretched along its velocity: the path each particle "
     "covers in the Streak Time"),
]

GLOW_MATERIAL = "physanim_glow"
SPRITE_MATERIAL = "physanim_sprite"
BLOB_MATERIAL = "physanim_blob"
BLOB_COLOR = "pa_color"  # Cycles reads a realized attribute named exactly "color" as black
_VERSION = 6


def apply(res: bpy.types.Object, p) -> bpy.types.NodesModifier:
    """Set up ``res`` (a particle result) to render as ``p.render_as`` (``p``: the emitter's
    settings)."""
    mode = p.render_as
    if mode == 'GLOW':
        group = instancing.ensure_group("physanim_glow", _build_glow, _VERSION)
        inputs = {"Material": glow_material(), "Strength": p.glow_strength}
    elif mode == 'STREAKS':
        group = instancing.ensure_group("physanim_streaks", _build_streaks, _VERSION)
        inputs = {"Instance": p.instance_object or instancing.default_particle_object(),
                  "Streak Time": p.streak_time}
    elif mode == 'BILLBOARD':
        group = instancing.ensure_group("physanim_billboards", _build_billboards, _VERSION)
        inputs = {"Material": sprite_material(p.sprite)}
    elif mode == 'BLOBS':
        group = instancing.ensure_group("physanim_blobs", _build_blobs, _VERSION)
        inputs = {"Material": blob_material(), "Blob Size": p.blob_size,
                  "Voxel Size": p.size * p.blob_size / p.blob_resolution}
    else:
        return instancing.ensure_instancer(res, p.instance_object)
    return instancing.ensure_modifier(res, group, inputs)


# --- node groups ---------------------------------------------------------------------------------

def _group_io(group, inputs):
    instancing.new_group_interface(group, inputs)
    group_in = group.nodes.new('NodeGroupInput')
    group_in.location = (-1400, 0)
    group_out = group.nodes.new('NodeGroupOutput')
    group_out.location = (600, 0)
    return group_in, group_out


def _build_glow(group) -> None:
    """Billboards whose points carry "glow" = Strength (read by the glow material)."""
    group_in, group_out = _group_io(group, [("Material", 'NodeSocketMaterial'),
                                            ("Strength", 'NodeSocketFloat')])
    store = _store(group, 'FLOAT', "glow", (-1300, 200))
    group.links.new(group_in.outputs["Geometry"], store.inputs["Geometry"])
    group.links.new(group_in.outputs["Strength"], _value_input(store))
    _billboards(group, store.outputs["Geometry"], group_in.outputs["Material"], group_out)


def _build_streaks(group) -> None:
    """Rotation: +Z along ``velocity``; scale (s, s, s + |v| t / 2), s = ``size`` (or 1)."""
    nodes, links = group.nodes, group.links
    group_in, group_out = _group_io(group, [("Instance", 'NodeSocketObject'),
                                            ("Streak Time", 'NodeSocketFloat')])
    velocity = instancing.named_attribute(group, "velocity", 'FLOAT_VECTOR', (-1200, -300))
    size = _size_or_one(group, (-1200, -500))
    align = nodes.new('FunctionNodeAlignRotationToVector')
    align.axis = 'Z'
    align.location = (-900, -300)
    links.new(velocity.outputs["Attribute"], align.inputs["Vector"])
    speed = _math(group, 'LENGTH', (-1000, -650), vector=True)
    links.new(velocity.outputs["Attribute"], speed.inputs[0])
    half = _math(group, 'MULTIPLY', (-800, -650))
    links.new(speed.outputs["Value"], half.inputs[0])
    links.new(group_in.outputs["Streak Time"], half.inputs[1])
    halved = _math(group, 'MULTIPLY', (-650, -650))
    links.new(half.outputs[0], halved.inputs[0])
    halved.inputs[1].default_value = 0.5
    length = _math(group, 'ADD', (-500, -600))
    links.new(size, length.inputs[0])
    links.new(halved.outputs[0], length.inputs[1])
    scale = nodes.new('ShaderNodeCombineXYZ')
    scale.location = (-300, -500)
    for axis in (0, 1):
        links.new(size, scale.inputs[axis])
    links.new(length.outputs[0], scale.inputs[2])
    instance = instancing.object_geometry(group, group_in.outputs["Instance"], (-500, -100))
    on_points = nodes.new('GeometryNodeInstanceOnPoints')
    on_points.location = (0, 0)
    links.new(group_in.outputs["Geometry"], on_points.inputs["Points"])
    links.new(instance, on_points.inputs["Instance"])
    links.new(align.outputs["Rotation"], on_points.inputs["Rotation"])
    links.new(scale.outputs["Vector"], on_points.inputs["Scale"])
    links.new(on_points.outputs["Instances"], group_out.inputs["Geometry"])


def _build_billboards(group) -> None:
    group_in, group_out = _group_io(group, [("Material", 'NodeSocketMaterial')])
    _billboards(group, group_in.outputs["Geometry"], group_in.outputs["Material"], group_out)


def _billboards(group, points, material_socket, group_out) -> None:
    """A 2 m square (radius 1, like the default sphere) with its UV map and ``material_socket``,
    on every point, turned to face the active camera and scaled by ``size``."""
    nodes, links = group.nodes, group.links
    grid = nodes.new('GeometryNodeMeshGrid')
    grid.location = (-1200, -100)
    for name, value in (("Size X", 2.0), ("Size Y", 2.0), ("Vertices X", 2), ("Vertices Y", 2)):
        grid.inputs[name].default_value = value
    uv = _store(group, 'FLOAT2', "UVMap", (-1000, -100), domain='CORNER')
    links.new(grid.outputs["Mesh"], uv.inputs["Geometry"])
    links.new(grid.outputs["UV Map"], _value_input(uv))
    material = nodes.new('GeometryNodeSetMaterial')
    material.location = (-800, -100)
    links.new(uv.outputs["Geometry"], material.inputs["Geometry"])
    links.new(material_socket, material.inputs["Material"])

    camera = nodes.new('GeometryNodeInputActiveCamera')
    camera.location = (-1200, -400)
    info = nodes.new('GeometryNodeObjectInfo')
    info.transform_space = 'RELATIVE'  # the camera in the result object's space, as the points
    info.location = (-1000, -400)
    links.new(camera.outputs["Active Camera"], info.inputs["Object"])
    position = nodes.new('GeometryNodeInputPosition')
    position.location = (-1000, -600)
    towards = _math(group, 'SUBTRACT', (-800, -450), vector=True)
    links.new(info.outputs["Location"], towards.inputs[0])
    links.new(position.outputs["Position"], towards.inputs[1])
    align = nodes.new('FunctionNodeAlignRotationToVector')
    align.axis = 'Z'
    align.location = (-600, -450)
    links.new(towards.outputs["Vector"], align.inputs["Vector"])
    on_points = nodes.new('GeometryNodeInstanceOnPoints')
    on_points.location = (0, 0)
    links.new(points, on_points.inputs["Points"])
    links.new(material.outputs["Geometry"], on_points.inputs["Instance"])
    links.new(align.outputs["Rotation"], on_points.inputs["Rotation"])
    links.new(_size_or_one(group, (-600, -700)), on_points.inputs["Scale"])
    links.new(on_points.outputs["Instances"], group_out.inputs["Geometry"])


def _build_blobs(group) -> None:
    """Points to Volume (radius = size x Blob Size) -> Volume to Mesh -> smooth, coloured by
    the nearest particle (``pa_color``) -> Material."""
    nodes, links = group.nodes, group.links
    group_in, group_out = _group_io(group, [("Material", 'NodeSocketMaterial'),
                                            ("Blob Size", 'NodeSocketFloat'),
                                            ("Voxel Size", 'NodeSocketFloat')])
    radius = _math(group, 'MULTIPLY', (-1100, -300))
    links.new(_size_or_one(group, (-1300, -300)), radius.inputs[0])
    links.new(group_in.outputs["Blob Size"], radius.inputs[1])
    volume = nodes.new('GeometryNodePointsToVolume')
    volume.location = (-900, 0)
    compat.volume_resolution_by_size(volume)
    links.new(group_in.outputs["Geometry"], volume.inputs["Points"])
    links.new(_voxel_floor(group, group_in, radius.outputs[0]), volume.inputs["Voxel Size"])
    links.new(radius.outputs[0], volume.inputs["Radius"])
    surface = nodes.new('GeometryNodeVolumeToMesh')
    surface.location = (-700, 0)
    surface.inputs["Threshold"].default_value = 0.5
    links.new(volume.outputs["Volume"], surface.inputs["Volume"])
    smooth = nodes.new('GeometryNodeSetShadeSmooth')
    smooth.location = (-500, 0)
    links.new(surface.outputs["Mesh"], smooth.inputs["Geometry"])

    nearest = nodes.new('GeometryNodeSampleNearest')
    nearest.location = (-700, -300)
    links.new(group_in.outputs["Geometry"], nearest.inputs["Geometry"])
    color = instancing.named_attribute(group, "color", 'FLOAT_COLOR', (-700, -500))
    sample = nodes.new('GeometryNodeSampleIndex')
    sample.data_type = 'FLOAT_COLOR'
    sample.location = (-500, -300)
    links.new(group_in.outputs["Geometry"], sample.inputs["Geometry"])
    links.new(color.outputs["Attribute"], _value_input(sample, "Value"))
    links.new(nearest.outputs["Index"], sample.inputs["Index"])
    store = _store(group, 'FLOAT_COLOR', BLOB_COLOR, (-300, 0))
    links.new(smooth.outputs["Geometry"], store.inputs["Geometry"])
    links.new(sample.outputs["Value"], _value_input(store))
    material = nodes.new('GeometryNodeSetMaterial')
    material.location = (0, 0)
    links.new(store.outputs["Geometry"], material.inputs["Geometry"])
    links.new(group_in.outputs["Material"], material.inputs["Material"])
    # No points, no surface: Volume to Mesh of an empty volume crashes Blender (4.5), so the
    # (lazy) switch does not build one at all.
    count = nodes.new('GeometryNodeAttributeStatistic')
    count.data_type, count.domain = 'FLOAT', 'POINT'
    count.inputs["Attribute"].default_value = 1.0
    count.location = (0, -300)
    links.new(group_in.outputs["Geometry"], count.inputs["Geometry"])
    some = nodes.new('FunctionNodeCompare')
    some.data_type, some.operation = 'FLOAT', 'GREATER_THAN'
    some.location = (200, -300)
    links.new(count.outputs["Sum"], some.inputs[0])
    any_points = _switch_geometry(group, (400, 0))
    links.new(some.outputs[0], any_points.inputs["Switch"])
    links.new(material.outputs["Geometry"], any_points.inputs["True"])
    links.new(group_in.outputs["Geometry"], any_points.inputs["False"])
    links.new(any_points.outputs["Output"], group_out.inputs["Geometry"])


def _switch_geometry(group, location):
    node = group.nodes.new('GeometryNodeSwitch')
    node.input_type = 'GEOMETRY'
    node.location = location
    return node


MAX_BLOB_VOXELS = 3.0e6  # a frame's blob volume at most (~12 MB of voxels, a few M vertices)
MAX_BLOB_INDEX = 1.0e6  # voxels from the origin to the farthest point, per axis


def _voxel_floor(group, group_in, radius):
    """The voxel size the volume uses: the Voxel Size input, but never so small that the blobs
    would need more than MAX_BLOB_VOXELS voxels (N points of radius up to r fill about
    N (2 r / v)^3) or a point would lie more than MAX_BLOB_INDEX voxels out (OpenVDB's index
    space) — a huge or far-flung cloud gets coarser blobs instead of exhausting memory."""
    nodes, links = group.nodes, group.links
    stats = nodes.new('GeometryNodeAttributeStatistic')
    stats.data_type, stats.domain = 'FLOAT', 'POINT'
    stats.location = (-1500, -700)
    links.new(group_in.outputs["Geometry"], stats.inputs["Geometry"])
    links.new(radius, stats.inputs["Attribute"])
    count = nodes.new('GeometryNodeAttributeStatistic')
    count.data_type, count.domain = 'FLOAT', 'POINT'
    count.location = (-1500, -950)
    count.inputs["Attribute"].default_value = 1.0
    links.new(group_in.outputs["Geometry"], count.inputs["Geometry"])
    share = _math(group, 'DIVIDE', (-1300, -950))
    links.new(count.outputs["Sum"], share.inputs[0])
    share.inputs[1].default_value = MAX_BLOB_VOXELS
    root = _math(group, 'POWER', (-1150, -950))
    links.new(share.outputs[0], root.inputs[0])
    root.inputs[1].default_value = 1.0 / 3.0
    crowd = _math(group, 'MULTIPLY', (-1000, -850))
    links.new(stats.outputs["Max"], crowd.inputs[0])
    links.new(root.outputs[0], crowd.inputs[1])
    crowd_floor = _math(group, 'MULTIPLY', (-850, -850))
    links.new(crowd.outputs[0], crowd_floor.inputs[0])
    crowd_floor.inputs[1].default_value = 2.0
    bounds = nodes.new('GeometryNodeBoundBox')
    bounds.location = (-1500, -1200)
    links.new(group_in.outputs["Geometry"], bounds.inputs["Geometry"])
    far = []
    for k, corner in enumerate(("Min", "Max")):
        absolute = _math(group, 'ABSOLUTE', (-1300, -1150 - 100 * k), vector=True)
        links.new(bounds.outputs[corner], absolute.inputs[0])
        far.append(absolute.outputs["Vector"])
    farthest = _math(group, 'MAXIMUM', (-1150, -1200), vector=True)
    links.new(far[0], farthest.inputs[0])
    links.new(far[1], farthest.inputs[1])
    xyz = nodes.new('ShaderNodeSeparateXYZ')
    xyz.location = (-1000, -1200)
    links.new(farthest.outputs["Vector"], xyz.inputs["Vector"])
    out = group_in.outputs["Voxel Size"]
    floors = [crowd_floor.outputs[0]]
    for axis in ("X", "Y", "Z"):  # a coordinate: at most MAX_BLOB_INDEX voxels out
        scale = _math(group, 'DIVIDE', (-850, -1200))
        links.new(xyz.outputs[axis], scale.inputs[0])
        scale.inputs[1].default_value = MAX_BLOB_INDEX
        floors.append(scale.outputs[0])
    for scaled in floors:
        larger = _math(group, 'MAXIMUM', (-700, -900))
        links.new(out, larger.inputs[0])
        links.new(scaled, larger.inputs[1])
        out = larger.outputs[0]
    return out


def _store(group, data_type: str, name: str, location, domain: str = 'POINT'):
    node = group.nodes.new('GeometryNodeStoreNamedAttribute')
    node.data_type = data_type
    node.domain = domain
    node.inputs["Name"].default_value = name
    node.location = location
    return node


def _value_input(node, name: str = "Value"):
    """The enabled input socket ``name`` of a node whose value socket follows its data type."""
    return next(s for s in node.inputs if s.name == name and s.enabled)


def _math(group, operation: str, location, vector: bool = False):
    node = group.nodes.new('ShaderNodeVectorMath' if vector else 'ShaderNodeMath')
    node.operation = operation
    node.location = location
    return node


def _size_or_one(group, location):
    """The ``size`` attribute, or 1 where the points have none: an output socket."""
    x, y = location
    size = instancing.named_attribute(group, "size", 'FLOAT', (x - 200, y))
    switch = group.nodes.new('GeometryNodeSwitch')
    switch.input_type = 'FLOAT'
    switch.location = (x, y)
    switch.inputs["False"].default_value = 1.0
    group.links.new(size.outputs["Exists"], switch.inputs["Switch"])
    group.links.new(size.outputs["Attribute"], switch.inputs["True"])
    return switch.outputs["Output"]


# --- objects and materials -----------------------------------------------------------------------

def _material(name: str, build) -> bpy.types.Material:
    material = instancing.find_built(bpy.data.materials, name)
    if material is not None and material.get(instancing.BUILT_TAG) == _VERSION:
        return material
    material = material or bpy.data.materials.new(name)
    tree = compat.set_material_use_nodes(material)
    tree.nodes.clear()
    build(material, tree.nodes, tree.links)
    instancing.tag(material, name, _VERSION)
    return material


def _instancer_attribute(nodes, name: str, location):
    node = nodes.new('ShaderNodeAttribute')
    node.attribute_type = 'INSTANCER'
    node.attribute_name = name
    node.location = location
    return node


def _soft_dot(nodes, links, location):
    """1 at a billboard's centre, falling to 0 at its edge (a spherical gradient over its UV
    square): the output socket."""
    x, y = location
    uv = nodes.new('ShaderNodeUVMap')
    uv.uv_map = "UVMap"
    uv.location = (x - 400, y)
    centre = nodes.new('ShaderNodeVectorMath')
    centre.operation = 'MULTIPLY_ADD'
    centre.inputs[1].default_value = (2.0, 2.0, 0.0)
    centre.inputs[2].default_value = (-1.0, -1.0, 0.0)
    centre.location = (x - 200, y)
    links.new(uv.outputs["UV"], centre.inputs[0])
    dot = nodes.new('ShaderNodeTexGradient')
    dot.gradient_type = 'SPHERICAL'
    dot.location = (x, y)
    links.new(centre.outputs["Vector"], dot.inputs["Vector"])
    return dot.outputs["Fac"]


def glow_material() -> bpy.types.Material:
    """Emission of the instance's ``color`` at strength ``glow`` x alpha x a soft falloff,
    added to a transparent surface: light without a body (additive)."""
    def build(material, nodes, links):
        color = _instancer_attribute(nodes, "color", (-600, 250))
        glow = _instancer_attribute(nodes, "glow", (-600, 0))
        falloff = nodes.new('ShaderNodeMath')
        falloff.operation = 'POWER'
        falloff.inputs[1].default_value = 2.0
        falloff.location = (-400, -250)
        links.new(_soft_dot(nodes, links, (-600, -250)), falloff.inputs[0])
        strength = nodes.new('ShaderNodeMath')
        strength.operation = 'MULTIPLY'
        strength.location = (-350, 0)
        links.new(compat.attribute_factor(glow), strength.inputs[0])
        links.new(color.outputs["Alpha"], strength.inputs[1])
        shaped = nodes.new('ShaderNodeMath')
        shaped.operation = 'MULTIPLY'
        shaped.location = (-200, -100)
        links.new(strength.outputs[0], shaped.inputs[0])
        links.new(falloff.outputs[0], shaped.inputs[1])
        emission = nodes.new('ShaderNodeEmission')
        emission.location = (-150, 150)
        links.new(color.outputs["Color"], emission.inputs["Color"])
        links.new(shaped.outputs[0], emission.inputs["Strength"])
        clear = nodes.new('ShaderNodeBsdfTransparent')
        clear.location = (-150, -100)
        add = nodes.new('ShaderNodeAddShader')
        add.location = (100, 0)
        links.new(emission.outputs[0], add.inputs[0])
        links.new(clear.outputs[0], add.inputs[1])
        output = nodes.new('ShaderNodeOutputMaterial')
        output.location = (300, 0)
        links.new(add.outputs[0], output.inputs["Surface"])
        compat.set_material_alpha(material)
    return _material(GLOW_MATERIAL, build)


def sprite_material(image: bpy.types.Image | None) -> bpy.types.Material:
    """Unlit sprite: the image (or a soft round dot) times the instance's ``color``, its alpha
    times the colour's alpha as coverage. One material per image."""
    name = SPRITE_MATERIAL if image is None else f"{SPRITE_MATERIAL}:{image.name}"

    def build(material, nodes, links):
        color = _instancer_attribute(nodes, "color", (-600, 250))
        tint = nodes.new('ShaderNodeMix')
        tint.data_type = 'RGBA'
        tint.blend_type = 'MULTIPLY'
        tint.inputs["Factor"].default_value = 1.0
        tint.location = (-300, 200)
        coverage = nodes.new('ShaderNodeMath')
        coverage.operation = 'MULTIPLY'
        coverage.location = (-300, -100)
        if image is not None:
            uv = nodes.new('ShaderNodeUVMap')
            uv.uv_map = "UVMap"
            uv.location = (-1000, 0)
            texture = nodes.new('ShaderNodeTexImage')
            texture.image = image
            texture.location = (-700, 0)
            links.new(uv.outputs["UV"], texture.inputs["Vector"])
            rgb, alpha = texture.outputs["Color"], texture.outputs["Alpha"]
        else:
            rgb, alpha = color.outputs["Color"], _soft_dot(nodes, links, (-600, -100))
        links.new(rgb, _value_input(tint, "A"))
        links.new(color.outputs["Color"], _value_input(tint, "B"))
        links.new(alpha, coverage.inputs[0])
        links.new(color.outputs["Alpha"], coverage.inputs[1])
        emission = nodes.new('ShaderNodeEmission')
        emission.location = (0, 150)
        links.new(next(o for o in tint.outputs if o.name == "Result" and o.enabled),
                  emission.inputs["Color"])
        clear = nodes.new('ShaderNodeBsdfTransparent')
        clear.location = (0, -50)
        mix = nodes.new('ShaderNodeMixShader')
        mix.location = (250, 0)
        links.new(coverage.outputs[0], mix.inputs["Fac"])
        links.new(clear.outputs[0], mix.inputs[1])
        links.new(emission.outputs[0], mix.inputs[2])
        output = nodes.new('ShaderNodeOutputMaterial')
        output.location = (450, 0)
        links.new(mix.outputs[0], output.inputs["Surface"])
        compat.set_material_alpha(material)
    return _material(name, build)


def blob_material() -> bpy.types.Material:
    """A glossy surface in the colour of the nearest particle (``pa_color``)."""
    def build(material, nodes, links):
        color = nodes.new('ShaderNodeAttribute')
        color.attribute_type = 'GEOMETRY'
        color.attribute_name = BLOB_COLOR
        color.location = (-400, 0)
        shader = nodes.new('ShaderNodeBsdfPrincipled')
        shader.inputs["Roughness"].default_value = 0.15
        output = nodes.new('ShaderNodeOutputMaterial')
        output.location = (300, 0)
        links.new(color.outputs["Color"], shader.inputs["Base Color"])
        links.new(shader.outputs["BSDF"], output.inputs["Surface"])
    return _material(BLOB_MATERIAL, build)
