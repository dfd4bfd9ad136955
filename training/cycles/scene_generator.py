"""Procedural, animated Cycles scenes for training and benchmarking the temporal denoiser.

``build_scene(seed)`` builds, with bpy and nothing but ``random.Random(seed)``, the kind of shot a
Blender artist renders: a room lit through its window, a dim room lit by one shaded lamp, a
sunlit or night street with buildings and trees, a studio product shot. Everything is made of
primitives, modifiers and procedural node textures, so no asset has to be downloaded. The scenes
are meant to reproduce the light transport and the noise of real renders (indirect light, small
bright emitters, glass, thin geometry, volumes, depth of field, motion blur, a moving camera and
moving objects that uncover what was behind them), not to look good: render settings, light path
settings, exposure and view transform stay at what a user gets by default.

``describe(scene)`` summarises what a built scene contains, read back from the scene itself.
"""

from __future__ import annotations

import colorsys
import math
import random
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import bmesh
import bpy
from mathutils import Euler, Matrix, Vector

KINDS = ("interior", "dim_interior", "exterior", "product", "night_exterior")
# How often each kind is drawn: daylight interiors and exteriors are what artists render most.
_KIND_WEIGHTS = (0.28, 0.16, 0.24, 0.20, 0.12)

# Feature rates over seeds (the brief of the data set: a quarter with depth of field, a quarter
# with motion blur, about a fifth with volumes).
_DOF_RATE = 0.25
_MOTION_BLUR_RATE = 0.25
# A room full of haze is the slowest thing to render here: fog is mostly outdoors.
_VOLUME_RATE = {"interior": 0.1, "dim_interior": 0.1, "exterior": 0.4, "product": 0.12,
                "night_exterior": 0.3}

# The world's importance map is built on one core at every render; Blender's automatic size
# costs seconds per frame at training resolutions, a smaller map samples a smooth sky as well.
_WORLD_MAP_RESOLUTION = 256

# Sky models by preference: the physical ones look like what artists pick; names differ
# between Blender 4.2 (NISHITA) and 5.x (SINGLE_ / MULTIPLE_SCATTERING).
_PHYSICAL_SKIES = ("NISHITA", "SINGLE_SCATTERING", "MULTIPLE_SCATTERING")
# Background strength that gives every sky model (sun disc off) about the same light on the
# ground, measured on bpy 5; Blender 4.2's NISHITA is the model 5.x calls SINGLE_SCATTERING.
_SKY_NORMALISATION = {"NISHITA": 0.12, "SINGLE_SCATTERING": 0.12, "MULTIPLE_SCATTERING": 0.08,
                      "HOSEK_WILKIE": 3.0, "PREETHAM": 0.5}

_ROLE = "affinity_role"


# --------------------------------------------------------------------------------------------
# Public API


def scene_kind(seed: int) -> str:
    """The kind of scene ``build_scene(seed)`` builds when no kind is given."""
    return _draw_kind(random.Random(seed))


def build_scene(seed: int, *, width: int = 160, height: int = 96, frames: int = 8,
                threads: int = 1, kind: str | None = None) -> bpy.types.Scene:
    """Replace the open file by the scene of ``seed``: same seed, same scene, bit for bit."""
    rng = random.Random(seed)
    natural = _draw_kind(rng)  # drawn even for a forced kind: the rest of the stream is the same
    kind = natural if kind is None else kind
    if kind not in KINDS:
        raise ValueError(f"unknown scene kind {kind!r}; known: {', '.join(KINDS)}")
    frames = max(1, int(frames))

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    _render_settings(scene, width, height, frames, threads)
    b = _Build(rng=rng, scene=scene, frames=frames, kind=kind)
    _BUILDERS[kind](b)
    _finish(b, seed)
    return scene


def describe(scene: bpy.types.Scene) -> dict:
    """What the scene contains, as plain JSON-able values, read from the scene itself."""
    objects = sorted(scene.objects, key=lambda o: o.name)
    roles = {o.name: o.get(_ROLE, "") for o in objects}
    camera = scene.camera
    lights = [_describe_light(o) for o in objects if o.type == "LIGHT"]
    emitters = [_describe_emitter(o) for o in objects if _pure_emitter(o)]
    materials = [m for o in objects for m in _object_materials(o)]
    movers = [o.name for o in objects if o.type not in ("CAMERA", "EMPTY") and _is_animated(o)]
    seed = scene.get("affinity_seed", -1)
    features = {
        "dof": bool(camera and camera.data.dof.use_dof),
        "motion_blur": bool(scene.render.use_motion_blur),
        "volume": any(_has_volume(m.node_tree) for m in materials)
        or bool(scene.world and _has_volume(scene.world.node_tree)),
        "thin": any(r == "thin" for r in roles.values())
        or any(m.type == "WIREFRAME" for o in objects for m in getattr(o, "modifiers", ())),
        "glass": any(_input_value(m, "Transmission Weight", 0.0) >= 0.5 for m in materials),
        "sparks": any(r == "spark" for r in roles.values()),
        "window": any(r == "window" for r in roles.values()),
        "shaded_lamp": any(r == "lampshade" for r in roles.values()),
        "sky": bool(scene.world and any(n.bl_idname == "ShaderNodeTexSky"
                                       for n in scene.world.node_tree.nodes)),
        "displacement": any(m.type == "DISPLACE" for o in objects
                            for m in getattr(o, "modifiers", ())),
        "camera_moves": bool(camera and _is_animated(camera)),
        "moving_light": any(_is_animated(o) for o in objects
                            if o.type == "LIGHT" or _pure_emitter(o)),
    }
    return {
        "kind": str(scene.get("affinity_kind", "")),
        "seed": int(seed) if str(seed).lstrip("-").isdigit() else seed,
        "frames": [scene.frame_start, scene.frame_end],
        "resolution": [scene.render.resolution_x, scene.render.resolution_y],
        "camera": _describe_camera(scene),
        "lights": lights,
        "emitters": emitters,
        "features": features,
        "moving_objects": movers,
        "objects": len(objects),
        "materials": len({m.name for m in materials}),
    }


# --------------------------------------------------------------------------------------------
# Build state and render settings


@dataclass
class _Build:
    rng: random.Random
    scene: bpy.types.Scene
    frames: int
    kind: str
    # Where the camera looks and what it should keep in focus; set by the composition.
    subject: bpy.types.Object | None = None
    # Axis-aligned box the camera must stay inside (interiors), or None.
    camera_bounds: tuple[Vector, Vector] | None = None
    camera_motion: str = "static"
    notes: dict = field(default_factory=dict)

    def chance(self, p: float) -> bool:
        return self.rng.random() < p

    def uniform(self, lo: float, hi: float) -> float:
        return self.rng.uniform(lo, hi)


def _draw_kind(rng: random.Random) -> str:
    return rng.choices(KINDS, weights=_KIND_WEIGHTS)[0]


def _render_settings(scene: bpy.types.Scene, width: int, height: int, frames: int,
                     threads: int) -> None:
    render = scene.render
    render.engine = "CYCLES"
    render.resolution_x, render.resolution_y = width, height
    render.resolution_percentage = 100
    render.threads_mode = "FIXED"
    render.threads = threads
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.frame_start, scene.frame_end = 1, frames


def _finish(b: _Build, seed: int) -> None:
    scene = b.scene
    # ID properties hold 32-bit integers; larger seeds are kept exactly as text.
    scene["affinity_seed"] = seed if -2**31 <= seed < 2**31 else str(seed)
    scene["affinity_kind"] = b.kind
    scene["affinity_camera_motion"] = b.camera_motion
    if b.chance(_DOF_RATE * (1.6 if b.kind == "product" else 1.0)):
        _depth_of_field(b)
    if b.chance(_MOTION_BLUR_RATE):
        scene.render.use_motion_blur = True
        scene.render.motion_blur_shutter = round(b.uniform(0.3, 0.5), 3)
    scene.frame_set(1)


# --------------------------------------------------------------------------------------------
# Meshes (bmesh, so that nothing depends on an operator's context)


def _link(b: _Build, obj: bpy.types.Object, role: str | None = None) -> bpy.types.Object:
    b.scene.collection.objects.link(obj)
    if role:
        obj[_ROLE] = role
    return obj


def _mesh_object(b: _Build, name: str, bm: bmesh.types.BMesh, material=None,
                 location=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), smooth: bool = False,
                 role: str | None = None) -> bpy.types.Object:
    for face in bm.faces:
        face.smooth = smooth
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    obj.rotation_euler = rotation
    if material is not None:
        mesh.materials.append(material)
    return _link(b, obj, role)


def _box(bm: bmesh.types.BMesh, size, center=(0.0, 0.0, 0.0)) -> None:
    # Scaled in the mesh, not the object, so that bevel widths are in metres on every side.
    matrix = Matrix.Translation(center) @ Matrix.Diagonal((*size, 1.0))
    bmesh.ops.create_cube(bm, size=1.0, matrix=matrix)


def _cylinder(bm: bmesh.types.BMesh, radius: float, depth: float, center=(0.0, 0.0, 0.0),
              segments: int = 16, radius_top: float | None = None) -> None:
    bmesh.ops.create_cone(bm, cap_ends=True, segments=segments, radius1=radius,
                          radius2=radius if radius_top is None else radius_top, depth=depth,
                          matrix=Matrix.Translation(center))


def _rod(bm: bmesh.types.BMesh, start, end, radius: float, segments: int = 8) -> None:
    """A cylinder from ``start`` to ``end``: legs, rails, spindles, poles."""
    start, end = Vector(start), Vector(end)
    axis = end - start
    rotation = axis.to_track_quat("Z", "Y").to_matrix().to_4x4()
    matrix = Matrix.Translation((start + end) / 2) @ rotation
    bmesh.ops.create_cone(bm, cap_ends=True, segments=segments, radius1=radius, radius2=radius,
                          depth=axis.length, matrix=matrix)


def _sphere(bm: bmesh.types.BMesh, radius: float, center=(0.0, 0.0, 0.0), segments: int = 24,
            rings: int = 12) -> None:
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=radius,
                              matrix=Matrix.Translation(center))


def _revolve(bm: bmesh.types.BMesh, profile: Sequence[tuple[float, float]], segments: int = 32,
             closed: bool = False, center=(0.0, 0.0, 0.0)) -> None:
    """Turn a (radius, height) profile around the Z axis: vases, glasses, shades, tori.

    The profile runs so that the solid lies to its left (outside up, inside down): the faces
    then point out of the solid, which glass needs for its inside and outside to be right.
    """
    cx, cy, cz = center
    rings = []
    for r, z in profile:
        if r < 1e-6:  # on the axis: one pole vertex shared by the whole ring
            rings.append([bm.verts.new((cx, cy, cz + z))] * segments)
            continue
        rings.append([bm.verts.new((cx + r * math.cos(2 * math.pi * k / segments),
                                    cy + r * math.sin(2 * math.pi * k / segments), cz + z))
                      for k in range(segments)])
    pairs = list(zip(rings, rings[1:]))
    if closed:
        pairs.append((rings[-1], rings[0]))
    for lower, upper in pairs:
        for k in range(segments):
            quad = [lower[k], lower[(k + 1) % segments], upper[(k + 1) % segments], upper[k]]
            face = [v for i, v in enumerate(quad) if v is not quad[i - 1]]
            if len(face) >= 3:
                bm.faces.new(face)


def _shell_profile(outer: Sequence[tuple[float, float]], wall: float,
                   bottom: bool = True) -> list[tuple[float, float]]:
    """A thin-walled vessel's profile from its outside (bottom to rim): cups, vases, bottles."""
    inner = [(max(r - wall, 0.0), max(z, outer[0][1] + wall)) for r, z in reversed(outer)]
    if not bottom:
        return list(outer) + inner
    return [(0.0, outer[0][1])] + list(outer) + inner + [(0.0, outer[0][1] + wall)]


def _torus(bm: bmesh.types.BMesh, major: float, minor: float, center=(0.0, 0.0, 0.0),
           segments: int = 32, sides: int = 12) -> None:
    profile = [(major + minor * math.cos(2 * math.pi * k / sides),
                minor * math.sin(2 * math.pi * k / sides)) for k in range(sides)]
    _revolve(bm, profile, segments=segments, closed=True, center=center)


def _bevel(obj: bpy.types.Object, width: float, segments: int = 2) -> None:
    mod = obj.modifiers.new("Bevel", "BEVEL")
    mod.width = width
    mod.segments = segments
    mod.limit_method = "ANGLE"


def _subsurf(obj: bpy.types.Object, levels: int) -> None:
    mod = obj.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = mod.render_levels = min(levels, 2)


def _displace(obj: bpy.types.Object, rng: random.Random, strength: float, scale: float) -> None:
    texture = bpy.data.textures.new(obj.name + "Displace",
                                    rng.choice(("CLOUDS", "VORONOI", "STUCCI", "MUSGRAVE")))
    texture.noise_scale = scale
    mod = obj.modifiers.new("Displace", "DISPLACE")
    mod.texture = texture
    mod.texture_coords = "OBJECT" if rng.random() < 0.5 else "LOCAL"
    mod.strength = strength
    mod.mid_level = 0.5


def _wireframe(obj: bpy.types.Object, thickness: float) -> None:
    mod = obj.modifiers.new("Wireframe", "WIREFRAME")
    mod.thickness = thickness
    mod.use_even_offset = True
    obj[_ROLE] = "thin"


def _array(obj: bpy.types.Object, count: int, offset) -> None:
    mod = obj.modifiers.new("Array", "ARRAY")
    mod.count = count
    mod.use_relative_offset = False
    mod.use_constant_offset = True
    mod.constant_offset_displace = offset


def _cable(b: _Build, name: str, start, end, sag: float, radius: float,
           material) -> bpy.types.Object:
    """A hanging wire as a bevelled curve (what artists draw cables with)."""
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = radius
    curve.bevel_resolution = 1
    spline = curve.splines.new("POLY")
    count = 12
    spline.points.add(count - 1)
    start, end = Vector(start), Vector(end)
    for i, point in enumerate(spline.points):
        t = i / (count - 1)
        p = start.lerp(end, t)
        p.z -= sag * 4.0 * t * (1.0 - t)
        point.co = (p.x, p.y, p.z, 1.0)
    curve.materials.append(material)
    return _link(b, bpy.data.objects.new(name, curve), "thin")


# --------------------------------------------------------------------------------------------
# Colours and materials


def _hsv(h: float, s: float, v: float) -> tuple[float, float, float, float]:
    return (*colorsys.hsv_to_rgb(h % 1.0, s, v), 1.0)


def _pale(rng: random.Random) -> tuple[float, float, float, float]:
    return _hsv(rng.random(), rng.uniform(0.0, 0.25), rng.uniform(0.45, 0.8))


def _vivid(rng: random.Random) -> tuple[float, float, float, float]:
    return _hsv(rng.random(), rng.uniform(0.45, 0.9), rng.uniform(0.15, 0.7))


def _wood_colour(rng: random.Random) -> tuple[float, float, float, float]:
    return _hsv(rng.uniform(0.05, 0.1), rng.uniform(0.45, 0.75), rng.uniform(0.08, 0.4))


def _darker(colour, factor: float) -> tuple[float, float, float, float]:
    return (colour[0] * factor, colour[1] * factor, colour[2] * factor, 1.0)


def _node_tree(owner) -> bpy.types.NodeTree:
    if owner.node_tree is None:  # Blender < 5 creates the node tree on request
        owner.use_nodes = True
    return owner.node_tree


def _principled(name: str, colour, roughness: float = 0.5, **inputs: float) -> bpy.types.Material:
    """A Principled BSDF material; keyword inputs use socket names with underscores."""
    material = bpy.data.materials.new(name)
    bsdf = _node_tree(material).nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = colour
    bsdf.inputs["Roughness"].default_value = roughness
    for socket, value in inputs.items():
        bsdf.inputs[socket.replace("_", " ")].default_value = value
    return material


def _single_shader(name: str, node_type: str, output: str, **inputs) -> bpy.types.Material:
    """A material whose only shader is one ``node_type`` node, wired to the output's
    ``output`` socket, its inputs set by name (underscores for spaces)."""
    material = bpy.data.materials.new(name)
    tree = _node_tree(material)
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    shader = tree.nodes.new(node_type)
    for socket, value in inputs.items():
        shader.inputs[socket.replace("_", " ")].default_value = value
    tree.links.new(shader.outputs[0], tree.nodes["Material Output"].inputs[output])
    return material


def _emitter(name: str, colour, strength: float) -> bpy.types.Material:
    """A pure Emission material: lamps and bulbs do not reflect."""
    return _single_shader(name, "ShaderNodeEmission", "Surface", Color=colour, Strength=strength)


def _volume(name: str, colour, density: float, anisotropy: float = 0.0) -> bpy.types.Material:
    """A homogeneous Principled Volume with no surface: fog, haze, dust in a sunbeam."""
    return _single_shader(name, "ShaderNodeVolumePrincipled", "Volume", Color=colour,
                          Density=density, Anisotropy=anisotropy)


def _translucent_shade(name: str, colour, translucency: float) -> bpy.types.Material:
    """Lampshade fabric: diffuse mixed with translucent, so the shade glows from inside."""
    material = bpy.data.materials.new(name)
    tree = _node_tree(material)
    bsdf = tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = colour
    bsdf.inputs["Roughness"].default_value = 0.9
    translucent = tree.nodes.new("ShaderNodeBsdfTranslucent")
    translucent.inputs["Color"].default_value = colour
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = translucency
    output = tree.nodes["Material Output"]
    tree.links.new(bsdf.outputs[0], mix.inputs[1])
    tree.links.new(translucent.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], output.inputs["Surface"])
    return material


# Which output of each texture node is its scalar pattern (names differ across versions).
_TEXTURES = {"noise": ("ShaderNodeTexNoise", 0), "voronoi": ("ShaderNodeTexVoronoi", 0),
             "brick": ("ShaderNodeTexBrick", 1), "checker": ("ShaderNodeTexChecker", 1),
             "wave": ("ShaderNodeTexWave", 1)}


def _pattern(tree: bpy.types.NodeTree, rng: random.Random, style: str, scale: float):
    """A procedural pattern in object space; returns its scalar output socket."""
    coords = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (scale, scale, scale)
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, rng.uniform(0.0, math.pi))
    tree.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
    node_type, output = _TEXTURES[style]
    texture = tree.nodes.new(node_type)
    texture.inputs["Scale"].default_value = 1.0
    if style == "noise":
        texture.inputs["Detail"].default_value = rng.uniform(1.0, 8.0)
        texture.inputs["Roughness"].default_value = rng.uniform(0.4, 0.7)
    elif style == "voronoi":
        texture.inputs["Randomness"].default_value = rng.uniform(0.6, 1.0)
    elif style == "brick":
        texture.inputs["Mortar Size"].default_value = rng.uniform(0.01, 0.04)
        texture.inputs["Color1"].default_value = (0.9, 0.9, 0.9, 1.0)
        texture.inputs["Color2"].default_value = (0.6, 0.6, 0.6, 1.0)
        texture.inputs["Mortar"].default_value = (0.0, 0.0, 0.0, 1.0)
    elif style == "wave":
        texture.inputs["Distortion"].default_value = rng.uniform(0.0, 8.0)
        texture.inputs["Detail"].default_value = rng.uniform(0.0, 4.0)
        texture.wave_type = rng.choice(("BANDS", "RINGS"))
    tree.links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
    return texture.outputs[output]


def _texturize(material: bpy.types.Material, rng: random.Random, style: str, scale: float,
               colour2=None, roughness: tuple[float, float] | None = None,
               bump: float = 0.0) -> bpy.types.Material:
    """Drive base colour, roughness and bump of a Principled material by one pattern."""
    tree = material.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    fac = _pattern(tree, rng, style, scale)
    if colour2 is not None:
        ramp = tree.nodes.new("ShaderNodeValToRGB")
        lo, hi = sorted((rng.uniform(0.0, 0.45), rng.uniform(0.55, 1.0)))
        ramp.color_ramp.elements[0].position, ramp.color_ramp.elements[1].position = lo, hi
        ramp.color_ramp.elements[0].color = tuple(bsdf.inputs["Base Color"].default_value)
        ramp.color_ramp.elements[1].color = colour2
        tree.links.new(fac, ramp.inputs[0])
        tree.links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    if roughness is not None:
        remap = tree.nodes.new("ShaderNodeMapRange")
        remap.inputs["To Min"].default_value, remap.inputs["To Max"].default_value = roughness
        tree.links.new(fac, remap.inputs["Value"])
        tree.links.new(remap.outputs["Result"], bsdf.inputs["Roughness"])
    if bump > 0.0:
        node = tree.nodes.new("ShaderNodeBump")
        node.inputs["Strength"].default_value = bump
        node.inputs["Distance"].default_value = rng.uniform(0.005, 0.05)
        tree.links.new(fac, node.inputs["Height"])
        tree.links.new(node.outputs["Normal"], bsdf.inputs["Normal"])
    return material


def _random_texture(material, rng: random.Random, scale: float, colour2=None,
                    styles=("noise", "voronoi", "wave", "checker", "brick")):
    rough = material.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value
    lo, hi = max(rough - rng.uniform(0.1, 0.3), 0.0), min(rough + rng.uniform(0.1, 0.3), 1.0)
    return _texturize(material, rng, rng.choice(styles), scale, colour2=colour2,
                      roughness=(lo, hi) if rng.random() < 0.7 else None,
                      bump=rng.uniform(0.05, 0.4) if rng.random() < 0.6 else 0.0)


def _wood(rng: random.Random, name: str = "Wood") -> bpy.types.Material:
    colour = _wood_colour(rng)
    material = _principled(name, colour, rng.uniform(0.25, 0.6),
                           Coat_Weight=rng.choice((0.0, 0.0, 0.5)))
    return _texturize(material, rng, "wave", rng.uniform(3.0, 9.0), colour2=_darker(colour, 0.55),
                      roughness=(0.25, 0.6), bump=rng.uniform(0.02, 0.15))


def _glass(rng: random.Random, name: str = "Glass", rough: bool | None = None,
           tint=None) -> bpy.types.Material:
    rough = rng.random() < 0.35 if rough is None else rough
    return _principled(name, tint or (1.0, 1.0, 1.0, 1.0),
                       rng.uniform(0.08, 0.35) if rough else rng.choice((0.0, 0.0, 0.02)),
                       Transmission_Weight=1.0, IOR=rng.uniform(1.45, 1.55))


def _metal(rng: random.Random, name: str = "Metal", brushed: bool | None = None
           ) -> bpy.types.Material:
    brushed = rng.random() < 0.35 if brushed is None else brushed
    colour = rng.choice(((0.9, 0.9, 0.9, 1.0), (0.95, 0.75, 0.45, 1.0), (0.95, 0.6, 0.5, 1.0),
                         (0.55, 0.55, 0.58, 1.0)))
    if not brushed:
        return _principled(name, colour, rng.uniform(0.02, 0.25), Metallic=1.0)
    material = _principled(name, colour, rng.uniform(0.2, 0.4), Metallic=1.0,
                           Anisotropic=rng.uniform(0.5, 0.9))
    return _texturize(material, rng, "noise", rng.uniform(20.0, 60.0), roughness=(0.2, 0.4),
                      bump=0.05)


def _plastic(rng: random.Random, name: str = "Plastic", colour=None) -> bpy.types.Material:
    return _principled(name, colour or _vivid(rng), rng.uniform(0.05, 0.6))


def _paint(rng: random.Random, name: str = "Paint", colour=None) -> bpy.types.Material:
    """Coated car paint: a rough, partly metallic base under a clear glossy coat."""
    return _principled(name, colour or _vivid(rng), rng.uniform(0.3, 0.6),
                       Metallic=rng.uniform(0.0, 0.8), Coat_Weight=1.0,
                       Coat_Roughness=rng.uniform(0.0, 0.08))


def _fabric(rng: random.Random, name: str = "Fabric", colour=None) -> bpy.types.Material:
    material = _principled(name, colour or _hsv(rng.random(), rng.uniform(0.1, 0.6),
                                                rng.uniform(0.1, 0.6)),
                           rng.uniform(0.75, 1.0), Sheen_Weight=rng.uniform(0.0, 0.6))
    return _texturize(material, rng, rng.choice(("noise", "wave", "checker")),
                      rng.uniform(20.0, 60.0), bump=rng.uniform(0.1, 0.4))


# --------------------------------------------------------------------------------------------
# Lights and worlds


def _aim(obj: bpy.types.Object, direction) -> None:
    """Point a light's (or camera's) -Z along ``direction``."""
    obj.rotation_euler = Vector(direction).to_track_quat("-Z", "Y").to_euler()


def _light(b: _Build, name: str, kind: str, energy: float, location=(0.0, 0.0, 0.0),
           colour=(1.0, 1.0, 1.0), role: str | None = None) -> bpy.types.Object:
    data = bpy.data.lights.new(name, kind)
    data.energy = energy
    data.color = colour[:3]
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    return _link(b, obj, role)


def _sun(b: _Build, direction, strength: float, colour, angle_deg: float) -> bpy.types.Object:
    sun = _light(b, "Sun", "SUN", strength, (0.0, 0.0, 10.0), colour)
    sun.data.angle = math.radians(angle_deg)
    _aim(sun, direction)
    return sun


def _area(b: _Build, name: str, location, target, size: float, power: float, colour,
          shape: str = "SQUARE") -> bpy.types.Object:
    light = _light(b, name, "AREA", power, location, colour)
    light.data.shape = shape
    light.data.size = size
    light.data.size_y = size * b.uniform(0.5, 1.0)
    _aim(light, Vector(target) - Vector(location))
    return light


def _point(b: _Build, name: str, location, power: float, radius: float, colour,
           role: str | None = None) -> bpy.types.Object:
    light = _light(b, name, "POINT", power, location, colour, role)
    light.data.shadow_soft_size = radius
    return light


def _warm(rng: random.Random) -> tuple[float, float, float]:
    return rng.choice(((1.0, 0.78, 0.55), (1.0, 0.85, 0.68), (1.0, 0.7, 0.45),
                       (1.0, 0.92, 0.82)))


def _sun_direction(elevation_deg: float, azimuth_deg: float) -> Vector:
    """The direction sunlight travels, for a sun at this elevation and compass azimuth."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return -Vector((math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)))


def _world(b: _Build) -> tuple[bpy.types.World, bpy.types.NodeTree]:
    world = bpy.data.worlds.new("World")
    b.scene.world = world
    return world, _node_tree(world)


def _sky_types() -> list[str]:
    node_type = bpy.types.ShaderNodeTexSky
    return [item.identifier for item in node_type.bl_rna.properties["sky_type"].enum_items]


def _sky_world(b: _Build, sun_direction: Vector, brightness: float) -> bpy.types.World:
    """A sky texture matching the sun lamp (its own sun disc off: the lamp is the sun)."""
    world, tree = _world(b)
    world.cycles.sampling_method = "MANUAL"
    world.cycles.sample_map_resolution = _WORLD_MAP_RESOLUTION
    background = tree.nodes["Background"]
    available = _sky_types()
    physical = [t for t in _PHYSICAL_SKIES if t in available]
    others = [t for t in ("HOSEK_WILKIE", "PREETHAM") if t in available]
    choices = physical * 3 + others  # the physical sky is what most artists use now
    if not choices or b.chance(0.1):
        return _gradient_world(b, world, tree, brightness)
    sky_type = b.rng.choice(choices)
    sky = tree.nodes.new("ShaderNodeTexSky")
    sky.sky_type = sky_type
    to_sun = -sun_direction.normalized()
    if sky_type in _PHYSICAL_SKIES:
        sky.sun_disc = False
        sky.sun_elevation = max(math.asin(max(min(to_sun.z, 1.0), -1.0)), math.radians(1.0))
        sky.sun_rotation = math.atan2(to_sun.x, to_sun.y) % (2 * math.pi)
        if hasattr(sky, "altitude"):
            sky.altitude = b.uniform(0.0, 500.0)
    else:
        sky.sun_direction = to_sun
        sky.turbidity = b.uniform(2.0, 5.0)
    background.inputs["Strength"].default_value = _SKY_NORMALISATION.get(sky_type, 1.0) * brightness
    tree.links.new(sky.outputs[0], background.inputs["Color"])
    return world


def _gradient_world(b: _Build, world: bpy.types.World, tree: bpy.types.NodeTree,
                    brightness: float) -> bpy.types.World:
    """Horizon-to-zenith colours for when no sky model fits (or an artist prefers flat light)."""
    coords = tree.nodes.new("ShaderNodeTexCoord")
    split = tree.nodes.new("ShaderNodeSeparateXYZ")
    ramp = tree.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].position = 0.5
    ramp.color_ramp.elements[0].color = _hsv(b.uniform(0.05, 0.12), b.uniform(0.1, 0.35), 0.9)
    ramp.color_ramp.elements[1].position = b.uniform(0.65, 0.9)
    ramp.color_ramp.elements[1].color = _hsv(b.uniform(0.55, 0.62), b.uniform(0.3, 0.6), 0.7)
    tree.links.new(coords.outputs["Generated"], split.inputs[0])
    tree.links.new(split.outputs["Z"], ramp.inputs[0])
    background = tree.nodes["Background"]
    tree.links.new(ramp.outputs["Color"], background.inputs["Color"])
    background.inputs["Strength"].default_value = 0.4 * brightness
    return world


def _flat_world(b: _Build, colour, strength: float) -> bpy.types.World:
    world, tree = _world(b)
    background = tree.nodes["Background"]
    background.inputs["Color"].default_value = colour
    background.inputs["Strength"].default_value = strength
    return world


def _haze(b: _Build, density: float) -> bpy.types.Object:
    """Atmospheric haze over the whole set. A world volume would hide the sun lamp (its
    shadow rays cross infinite haze), so it is a large box, as artists build it."""
    return _fog_box(b, "Haze", (0.0, 10.0, 15.0), (160.0, 160.0, 30.0), density)


# --------------------------------------------------------------------------------------------
# Animation


def _fcurves(owner) -> Iterable[bpy.types.FCurve]:
    action = owner.animation_data.action
    if hasattr(action, "fcurves"):  # before Blender 5 an action holds its curves directly
        return action.fcurves
    from bpy_extras import anim_utils  # Blender 5: curves live in the slot's channel bag
    bag = anim_utils.action_get_channelbag_for_slot(action, owner.animation_data.action_slot)
    return bag.fcurves if bag is not None else ()


def _animate(b: _Build, obj: bpy.types.Object, pose: Callable[[int], dict],
             every_frame: bool = True, interpolation: str | None = None) -> None:
    """Key ``pose(i)`` (property -> value at frame index i) at every frame, or the two ends."""
    if b.frames < 2:
        return
    indices = range(b.frames) if every_frame else (0, b.frames - 1)
    for i in indices:
        for path, value in pose(i).items():
            setattr(obj, path, value)
            obj.keyframe_insert(path, frame=b.scene.frame_start + i)
    interpolation = interpolation or b.rng.choice(("LINEAR", "BEZIER"))
    for curve in _fcurves(obj):
        for key in curve.keyframe_points:
            key.interpolation = interpolation


def _swing(amplitude: float, speed: float, i: int) -> float:
    """Back-and-forth motion that starts at ``speed`` per frame and never leaves ``amplitude``:
    long sequences keep their speed without walking the camera out of the room."""
    if amplitude <= 0.0:
        return 0.0
    return amplitude * math.sin(speed * i / amplitude)


def _spin(b: _Build, obj: bpy.types.Object, degrees_per_frame: float, axis: int = 2) -> None:
    start = Euler(obj.rotation_euler)
    step = math.radians(degrees_per_frame)

    def pose(i: int) -> dict:
        rotation = Euler(start)
        rotation[axis] += step * i
        return {"rotation_euler": rotation}

    _animate(b, obj, pose, every_frame=False, interpolation="LINEAR")
    obj[_ROLE] = obj.get(_ROLE, "mover")


def _slide(b: _Build, obj: bpy.types.Object, velocity: Vector, roll_radius: float = 0.0) -> None:
    """Constant-velocity motion; a ball of ``roll_radius`` also rolls as it goes."""
    start = Vector(obj.location)
    start_rotation = Euler(obj.rotation_euler)
    axis = Vector((0.0, 0.0, 1.0)).cross(velocity)

    def pose(i: int) -> dict:
        values = {"location": start + velocity * i}
        if roll_radius > 0.0 and axis.length > 0.0:
            angle = velocity.length * i / roll_radius
            rolled = (Matrix.Rotation(angle, 3, axis.normalized())
                      @ start_rotation.to_matrix())
            values["rotation_euler"] = rolled.to_euler()
        return values

    _animate(b, obj, pose, every_frame=roll_radius > 0.0, interpolation="LINEAR")
    if obj.get(_ROLE) is None:
        obj[_ROLE] = "mover"


def _bob(b: _Build, obj: bpy.types.Object, amplitude: float, period: float) -> None:
    start = Vector(obj.location)
    phase = b.uniform(0.0, 2 * math.pi)
    _animate(b, obj, lambda i: {"location": start + Vector(
        (0.0, 0.0, amplitude * math.sin(phase + 2 * math.pi * i / period)))})


def _pendulum(b: _Build, obj: bpy.types.Object, degrees: float, period: float) -> None:
    """Swing about the object's origin (a pendant lamp hanging from its cable)."""
    start = Euler(obj.rotation_euler)
    phase = b.uniform(0.0, 2 * math.pi)
    axis = b.rng.choice((0, 1))

    def pose(i: int) -> dict:
        rotation = Euler(start)
        rotation[axis] += math.radians(degrees) * math.sin(phase + 2 * math.pi * i / period)
        return {"rotation_euler": rotation}

    _animate(b, obj, pose, interpolation="BEZIER")


def _crossing(b: _Build, obj: bpy.types.Object, camera_location: Vector, target: Vector,
              depth_fraction: float, width_fraction: float) -> None:
    """Move ``obj`` across the view between camera and target so that it uncovers what it hid.

    It crosses at ``width_fraction`` of the frame width per frame, about ``depth_fraction`` of
    the way from the camera to the target, passing the view centre mid-sequence. A ball
    (``roll_radius`` set) rolls on the floor, pushed back until the floor there is in view; if
    the floor is never in view it floats on the line of sight instead.
    """
    view = target - camera_location
    flat = Vector((view.x, view.y, 0.0))
    right = flat.cross(Vector((0.0, 0.0, 1.0))).normalized()
    radius = float(obj.get("roll_radius", 0.0))
    fraction = depth_fraction
    if radius > 0.0:
        half_height = math.atan(math.tan(_horizontal_fov(b) / 2.0) * b.scene.render.resolution_y
                                / b.scene.render.resolution_x)
        below = half_height * 0.8 - math.atan2(view.z, flat.length)
        reach = ((camera_location.z - radius) / math.tan(below) / flat.length
                 if below > 0.01 else math.inf)
        fraction = max(fraction, reach)
        if fraction > 1.5:
            fraction, radius = depth_fraction, 0.0
            obj["roll_radius"] = 0.0
    centre = camera_location + view * fraction
    depth = view.length * fraction
    frame_width = 2.0 * depth * math.tan(_horizontal_fov(b) / 2.0)
    speed = frame_width * width_fraction
    direction = b.rng.choice((-1.0, 1.0))
    travel = speed * (b.frames - 1)
    start = centre - right * direction * (travel / 2.0 + b.uniform(-0.2, 0.2) * frame_width)
    obj.location = (start.x, start.y, radius if radius > 0.0 else centre.z)
    _slide(b, obj, right * direction * speed, roll_radius=radius)


# --------------------------------------------------------------------------------------------
# Camera


def _horizontal_fov(b: _Build) -> float:
    camera = b.scene.camera.data
    return 2.0 * math.atan(camera.sensor_width / 2.0 / camera.lens)


def _camera(b: _Build, location, target, lens: float) -> bpy.types.Object:
    data = bpy.data.cameras.new("Camera")
    data.lens = lens
    data.clip_start = 0.05
    camera = _link(b, bpy.data.objects.new("Camera", data))
    camera.location = location
    b.scene.camera = camera
    aim = _link(b, bpy.data.objects.new("CameraTarget", None))
    aim.location = target
    return camera


def _track(camera: bpy.types.Object, aim: bpy.types.Object) -> None:
    constraint = camera.constraints.new("TRACK_TO")
    constraint.target = aim
    constraint.track_axis = "TRACK_NEGATIVE_Z"
    constraint.up_axis = "UP_Y"


def _camera_motion(b: _Build, styles: Sequence[str], weights: Sequence[float],
                   travel: float) -> None:
    """Animate the camera in one of ``styles``, at 1-5 % of the frame width per frame (now and
    then faster), staying within ``travel`` metres (or degrees of pan/orbit scaled from it)."""
    camera = b.scene.camera
    aim = b.scene.objects["CameraTarget"]
    style = b.rng.choices(styles, weights=weights)[0]
    b.camera_motion = style
    origin, target = Vector(camera.location), Vector(aim.location)
    view = target - origin
    distance = view.length
    forward = view.normalized()
    right = forward.cross(Vector((0.0, 0.0, 1.0))).normalized()
    rate = b.uniform(0.01, 0.05) if b.chance(0.85) else b.uniform(0.06, 0.12)
    speed = rate * 2.0 * distance * math.tan(_horizontal_fov(b) / 2.0)  # metres per frame
    straight = b.frames * speed <= travel and b.chance(0.5)

    if style == "pan":
        # A tripod pan: keyed rotation, no constraint.
        _aim(camera, view)
        start = Euler(camera.rotation_euler)
        step = rate * _horizontal_fov(b)
        sign = b.rng.choice((-1.0, 1.0))
        limit = math.radians(25.0)
        tilt = b.uniform(-0.3, 0.3) * step

        def pan(i: int) -> dict:
            rotation = Euler(start)
            rotation.z += sign * _swing(limit, step, i)
            rotation.x += _swing(limit / 3.0, tilt, i)
            return {"rotation_euler": rotation}

        _animate(b, camera, pan)
        return
    _track(camera, aim)
    if style == "static":
        return
    if style == "orbit":
        sign = b.rng.choice((-1.0, 1.0))
        offset = origin - target
        radius = max(offset.xy.length, 1e-3)
        limit = travel / radius

        def orbit(i: int) -> dict:
            angle = sign * (speed / radius * i if limit > 6.0 else _swing(limit, speed / radius, i))
            return {"location": target + Matrix.Rotation(angle, 3, "Z") @ offset}

        _animate(b, camera, orbit)
        return
    direction = {"dolly": forward * b.rng.choice((-1.0, 1.0)),
                 "truck": right * b.rng.choice((-1.0, 1.0)),
                 "crane": Vector((0.0, 0.0, b.rng.choice((-1.0, 1.0))))}[style]
    if style == "dolly":
        speed *= 2.0  # moving along the view changes the image less than moving across it
        travel = min(travel, distance * 0.5)  # never into what it looks at
    follow = style == "truck" and b.chance(0.5)  # the target slides along: a true truck shot

    def move(i: int) -> dict:
        shift = direction * (speed * i if straight else _swing(travel, speed, i))
        return {"location": _clamp(b, origin + shift)}

    _animate(b, camera, move, every_frame=not straight)
    if follow:
        _animate(b, aim, lambda i: {"location": target + move(i)["location"] - origin},
                 every_frame=not straight)


def _clamp(b: _Build, p: Vector) -> Vector:
    if b.camera_bounds is None:
        return p
    lo, hi = b.camera_bounds
    return Vector(tuple(min(max(p[k], lo[k]), hi[k]) for k in range(3)))


def _depth_of_field(b: _Build) -> None:
    dof = b.scene.camera.data.dof
    dof.use_dof = True
    dof.focus_object = b.subject or b.scene.objects["CameraTarget"]
    dof.aperture_fstop = round(b.uniform(0.8, 4.0), 2)


# --------------------------------------------------------------------------------------------
# Props shared by the kinds


def _lamp_bulb(b: _Build, name: str, centre: Vector, strength_range, power_range,
               colour) -> list[bpy.types.Object]:
    """A small, very bright bulb: an emissive sphere, a point light of tiny radius, or both
    (then the sphere casts no shadow, so the point light shines through it)."""
    style = b.rng.choice(("mesh", "point", "both"))
    made = []
    if style in ("mesh", "both"):
        radius = b.uniform(0.01, 0.05)
        bm = bmesh.new()
        _sphere(bm, radius, segments=12, rings=6)
        bulb = _mesh_object(b, name + "Bulb", bm, _emitter(name + "Bulb", (*colour, 1.0),
                                                           b.uniform(*strength_range)),
                            location=centre, smooth=True, role="spark")
        if style == "both":
            bulb.visible_shadow = False
        made.append(bulb)
    if style in ("point", "both"):
        made.append(_point(b, name + "Light", centre, b.uniform(*power_range),
                           b.uniform(0.0, 0.02), colour, role="spark"))
    return made


def _shade_profile(b: _Build, bottom: float, top: float, height: float) -> list:
    wall = 0.004
    return [(bottom, 0.0), (top, height), (top - wall, height), (bottom - wall, 0.0)]


def _shaded_lamp(b: _Build, name: str, base: Vector, style: str, strength_range,
                 power_range) -> dict:
    """A floor, table or pendant lamp: an open shade around a small bright bulb."""
    colour = _warm(b.rng)
    parts: dict = {}
    if style == "pendant":
        height = b.uniform(0.15, 0.3)
        bottom = b.uniform(0.15, 0.3)
        top = b.uniform(0.03, 0.08)
        shade_z = base.z - height  # a pendant's base is the top of its shade
        shade_material = (_metal(b.rng, name + "Shade", brushed=False) if b.chance(0.5)
                          else _translucent_shade(name + "Shade", _pale(b.rng), 0.4))
    else:
        pole_height = b.uniform(1.2, 1.6) if style == "floor" else b.uniform(0.25, 0.45)
        height = b.uniform(0.18, 0.3)
        bottom = b.uniform(0.14, 0.25) if style == "floor" else b.uniform(0.1, 0.16)
        top = bottom * b.uniform(0.5, 0.9)
        shade_z = base.z + pole_height - height * 0.6
        shade_material = _translucent_shade(name + "Shade", _pale(b.rng), b.uniform(0.2, 0.6))
        stand = bmesh.new()
        _cylinder(stand, b.uniform(0.08, 0.15), 0.03, center=(0, 0, 0.015), segments=24)
        # The pole stops under the bulb: a bulb inside the pole would light nothing.
        _rod(stand, (0, 0, 0.02), (0, 0, pole_height - height * 0.25 - 0.07),
             b.uniform(0.008, 0.015))
        parts["stand"] = _mesh_object(b, name + "Stand", stand, _metal(b.rng, name + "Stand"),
                                      location=base, smooth=True, role="thin")
    bm = bmesh.new()
    _revolve(bm, _shade_profile(b, bottom, top, height), segments=32, closed=True)
    parts["shade"] = _mesh_object(b, name + "Shade", bm, shade_material,
                                  location=(base.x, base.y, shade_z), smooth=True,
                                  role="lampshade")
    parts["bulbs"] = _lamp_bulb(b, name, Vector((base.x, base.y, shade_z + height * 0.35)),
                                strength_range, power_range, colour)
    return parts


def _pendant(b: _Build, name: str, ceiling: float, x: float, y: float, drop: float,
             strength_range, power_range) -> dict:
    """A lamp hanging from the ceiling on its cable; everything parented to the cable's top so
    that it can swing."""
    pivot = _link(b, bpy.data.objects.new(name + "Pivot", None))
    pivot.location = (x, y, ceiling)
    cable = bmesh.new()
    _rod(cable, (0, 0, 0), (0, 0, -drop), b.uniform(0.003, 0.006), segments=6)
    black = _principled(name + "Cable", (0.02, 0.02, 0.02, 1.0), 0.4)
    parts = {"cable": _mesh_object(b, name + "Cable", cable, black, role="thin")}
    parts.update(_shaded_lamp(b, name, Vector((0.0, 0.0, -drop)), "pendant",
                              strength_range, power_range))
    for obj in [parts["cable"], parts["shade"], *parts["bulbs"]]:
        obj.parent = pivot
    parts["pivot"] = pivot
    return parts


def _vessel(b: _Build, name: str, location, material, shape: str | None = None,
            scale: float = 1.0) -> bpy.types.Object:
    """A cup, vase, bottle, bowl or wine glass, turned from a profile."""
    shape = shape or b.rng.choice(("cup", "vase", "bottle", "bowl", "wineglass"))
    r = b.uniform(0.8, 1.2) * scale
    if shape == "cup":
        outer = [(0.035 * r, 0.0), (0.04 * r, 0.05 * r), (0.042 * r, 0.09 * r)]
        profile = _shell_profile(outer, 0.004)
    elif shape == "vase":
        outer = [(0.05 * r, 0.0), (0.09 * r, 0.08 * r), (0.08 * r, 0.18 * r),
                 (0.04 * r, 0.26 * r), (0.05 * r, 0.3 * r)]
        profile = _shell_profile(outer, 0.006)
    elif shape == "bottle":
        outer = [(0.04 * r, 0.0), (0.042 * r, 0.16 * r), (0.035 * r, 0.2 * r),
                 (0.013 * r, 0.24 * r), (0.013 * r, 0.3 * r)]
        profile = _shell_profile(outer, 0.003)
    elif shape == "bowl":
        outer = [(0.04 * r, 0.0)] + [(0.04 * r + 0.09 * r * math.sin(t / 6 * math.pi / 2),
                                      0.07 * r * (1 - math.cos(t / 6 * math.pi / 2)))
                                     for t in range(1, 7)]
        profile = _shell_profile(outer, 0.005)
    else:  # a wine glass: foot, thin stem, bowl
        profile = [(0.0, 0.0), (0.035 * r, 0.0), (0.035 * r, 0.003), (0.004 * r, 0.01 * r),
                   (0.004 * r, 0.09 * r), (0.03 * r, 0.11 * r), (0.04 * r, 0.15 * r),
                   (0.035 * r, 0.2 * r), (0.033 * r, 0.2 * r), (0.038 * r, 0.15 * r),
                   (0.028 * r, 0.113 * r), (0.0, 0.1 * r)]
    bm = bmesh.new()
    _revolve(bm, profile, segments=24)
    return _mesh_object(b, name, bm, material, location=location, smooth=True,
                        role="thin" if shape == "wineglass" else None)


def _suzanne(b: _Build, name: str, location, size: float, material, levels: int = 1
             ) -> bpy.types.Object:
    bm = bmesh.new()
    bmesh.ops.create_monkey(bm, matrix=Matrix.Diagonal((size / 2.7, size / 2.7, size / 2.7, 1)))
    # Suzanne looks along -Y, where the cameras stand; a slight turn keeps her from posing.
    obj = _mesh_object(b, name, bm, material, location=location,
                       rotation=(0.0, 0.0, b.uniform(-0.6, 0.6)), smooth=True)
    _subsurf(obj, levels)
    return obj


def _wire_ball(b: _Build, name: str, location, radius: float) -> bpy.types.Object:
    bm = bmesh.new()
    if b.chance(0.5):
        bmesh.ops.create_icosphere(bm, subdivisions=b.rng.choice((1, 2)), radius=radius)
    else:
        _sphere(bm, radius, segments=b.rng.choice((12, 16, 24)), rings=b.rng.choice((6, 8, 12)))
    obj = _mesh_object(b, name, bm, _metal(b.rng, name), location=location)
    _wireframe(obj, b.uniform(0.004, 0.015) * max(radius / 0.2, 0.5))
    return obj


def _rolling_ball(b: _Build, name: str, location, radius: float, material) -> bpy.types.Object:
    bm = bmesh.new()
    _sphere(bm, radius, segments=24, rings=12)
    obj = _mesh_object(b, name, bm, material, location=(location[0], location[1], radius),
                       smooth=True)
    obj["roll_radius"] = radius
    return obj


def _tiny_light(b: _Build, name: str, location, radius: float, colour,
                strength: float) -> bpy.types.Object:
    """One small, very bright emissive sphere: the fireflies a denoiser has to keep."""
    bm = bmesh.new()
    _sphere(bm, radius, segments=8, rings=4)
    return _mesh_object(b, name, bm, _emitter(name, colour, strength), location=location,
                        smooth=True, role="spark")


def _string_lights(b: _Build, name: str, start, end, sag: float, count: int,
                   strength_range) -> None:
    """Fairy or festoon lights: tiny bright bulbs along a sagging wire."""
    start, end = Vector(start), Vector(end)
    _cable(b, name + "Wire", start, end, sag, 0.002,
           _principled(name + "Wire", (0.02, 0.02, 0.02, 1.0), 0.4))
    colour = _hsv(b.uniform(0.05, 0.15), b.uniform(0.0, 0.6), 1.0)
    radius = b.uniform(0.01, 0.025)
    for k in range(count):
        t = (k + 0.5) / count
        p = start.lerp(end, t)
        p.z -= sag * 4.0 * t * (1.0 - t) + radius
        _tiny_light(b, f"{name}{k}", p, radius, colour, b.uniform(*strength_range))


def _candles(b: _Build, centre: Vector, count: int) -> None:
    """Candles on the table: wax cylinders under small, very bright flames."""
    wax = _principled("Wax", _hsv(0.1, b.uniform(0.0, 0.2), 0.8), 0.4)
    for k in range(count):
        spot = centre + Vector((b.uniform(-0.25, 0.25), b.uniform(-0.15, 0.15), 0.0))
        radius, height = b.uniform(0.01, 0.025), b.uniform(0.05, 0.18)
        bm = bmesh.new()
        _cylinder(bm, radius, height, center=(0.0, 0.0, height / 2), segments=12)
        _mesh_object(b, f"Candle{k}", bm, wax, location=spot, smooth=True)
        _tiny_light(b, f"Flame{k}", spot + Vector((0.0, 0.0, height + 0.012)),
                    b.uniform(0.005, 0.01), (1.0, 0.6, 0.25, 1.0), b.uniform(100.0, 1000.0))


def _fog_box(b: _Build, name: str, centre, size, density: float) -> bpy.types.Object:
    bm = bmesh.new()
    _box(bm, size)
    fog = _volume(name, (0.9, 0.92, 0.95, 1.0), density, b.uniform(0.0, 0.7))
    return _mesh_object(b, name, bm, fog, location=centre, role="volume")


# --------------------------------------------------------------------------------------------
# Interiors


@dataclass
class _Room:
    width: float
    depth: float
    height: float
    wall: float
    windows: list  # (x0, x1, z0, z1) openings in the back wall (y = +depth / 2)
    door: tuple | None  # (y0, y1, height) opening in the right wall (x = +width / 2)


def _wall(b: _Build, name: str, length: float, height: float, thickness: float,
          openings: Sequence[tuple[float, float, float, float]], matrix: Matrix,
          material) -> bpy.types.Object:
    """A wall of boxes around rectangular openings, in wall space (u along, z up)."""
    bm = bmesh.new()
    cuts = sorted(openings)
    u = -length / 2
    for u0, u1, z0, z1 in cuts:
        if u0 > u:
            _box(bm, (u0 - u, thickness, height), ((u + u0) / 2, 0.0, height / 2))
        if z0 > 0.0:
            _box(bm, (u1 - u0, thickness, z0), ((u0 + u1) / 2, 0.0, z0 / 2))
        if z1 < height:
            _box(bm, (u1 - u0, thickness, height - z1), ((u0 + u1) / 2, 0.0, (z1 + height) / 2))
        u = u1
    if u < length / 2:
        _box(bm, (length / 2 - u, thickness, height), ((u + length / 2) / 2, 0.0, height / 2))
    bmesh.ops.transform(bm, matrix=matrix, verts=bm.verts)
    return _mesh_object(b, name, bm, material)


def _room(b: _Build, room: _Room, closed_front: bool = True) -> None:
    """Floor, ceiling and four walls; windows in the back wall, a door gap in the right one."""
    w, d, h, t = room.width, room.depth, room.height, room.wall
    wall_colour = _pale(b.rng)
    walls = _principled("WallPaint", wall_colour, b.uniform(0.5, 0.9))
    if b.chance(0.5):
        _texturize(walls, b.rng, "noise", b.uniform(5.0, 30.0), bump=b.uniform(0.05, 0.2))
    floor = _floor_material(b)
    ceiling = _principled("Ceiling", (0.75, 0.75, 0.73, 1.0), 0.9)

    bm = bmesh.new()
    _box(bm, (w + 2 * t, d + 2 * t, t), (0.0, 0.0, -t / 2))
    _mesh_object(b, "Floor", bm, floor)
    bm = bmesh.new()
    _box(bm, (w + 2 * t, d + 2 * t, t), (0.0, 0.0, h + t / 2))
    _mesh_object(b, "Ceiling", bm, ceiling)
    skirting = b.chance(0.5)

    back = [(x0, x1, z0, z1) for x0, x1, z0, z1 in room.windows]
    _wall(b, "WallBack", w + 2 * t, h, t, back,
          Matrix.Translation((0.0, d / 2 + t / 2, 0.0)), walls)
    _wall(b, "WallLeft", d, h, t, [],
          Matrix.Translation((-w / 2 - t / 2, 0.0, 0.0)) @ Matrix.Rotation(math.pi / 2, 4, "Z"),
          walls)
    door = [] if room.door is None else [(room.door[0], room.door[1], 0.0, room.door[2])]
    _wall(b, "WallRight", d, h, t, door,
          Matrix.Translation((w / 2 + t / 2, 0.0, 0.0)) @ Matrix.Rotation(math.pi / 2, 4, "Z"),
          walls)
    if closed_front:
        _wall(b, "WallFront", w + 2 * t, h, t, [],
              Matrix.Translation((0.0, -d / 2 - t / 2, 0.0)), walls)
    if skirting:
        bm = bmesh.new()
        for size, centre in (((w, 0.015, 0.08), (0, d / 2 - 0.0075, 0.04)),
                             ((0.015, d, 0.08), (-w / 2 + 0.0075, 0, 0.04))):
            _box(bm, size, centre)
        _mesh_object(b, "Skirting", bm, _principled("Skirting", (0.7, 0.7, 0.68, 1.0), 0.4))
    for k, (x0, x1, z0, z1) in enumerate(room.windows):
        _window_frame(b, f"Window{k}", x0, x1, z0, z1, d / 2 + t / 2, t)


def _floor_material(b: _Build) -> bpy.types.Material:
    style = b.rng.choice(("wood", "wood", "tiles", "concrete", "carpet"))
    if style == "wood":
        material = _wood(b.rng, "FloorWood")
        if b.chance(0.5):  # planks
            _texturize(material, b.rng, "brick", b.uniform(1.0, 3.0), bump=0.2)
        return material
    if style == "tiles":
        colour = _pale(b.rng)
        material = _principled("FloorTiles", colour, b.uniform(0.05, 0.4))
        return _texturize(material, b.rng, b.rng.choice(("checker", "brick")),
                          b.uniform(1.5, 4.0), colour2=_darker(colour, b.uniform(0.3, 0.8)),
                          roughness=(0.05, 0.5), bump=0.1)
    if style == "concrete":
        material = _principled("FloorConcrete", _hsv(0.1, 0.05, b.uniform(0.25, 0.5)), 0.7)
        return _texturize(material, b.rng, "noise", b.uniform(2.0, 8.0),
                          colour2=_hsv(0.1, 0.05, 0.2), roughness=(0.4, 0.9), bump=0.1)
    return _fabric(b.rng, "FloorCarpet")


def _window_frame(b: _Build, name: str, x0: float, x1: float, z0: float, z1: float,
                  y: float, depth: float) -> None:
    """Frame and mullions: thin bars the sunlight and the sky are seen through."""
    bar = b.uniform(0.03, 0.06)
    bm = bmesh.new()
    xm, zm = (x0 + x1) / 2, (z0 + z1) / 2
    _box(bm, (x1 - x0, bar, bar), (xm, y, z0 + bar / 2))
    _box(bm, (x1 - x0, bar, bar), (xm, y, z1 - bar / 2))
    _box(bm, (bar, bar, z1 - z0), (x0 + bar / 2, y, zm))
    _box(bm, (bar, bar, z1 - z0), (x1 - bar / 2, y, zm))
    slim = bar * b.uniform(0.3, 0.6)
    columns = b.rng.choice((1, 2, 3))
    for k in range(1, columns):
        _box(bm, (slim, slim, z1 - z0), (x0 + (x1 - x0) * k / columns, y, zm))
    if b.chance(0.7):
        _box(bm, (x1 - x0, slim, slim), (xm, y, z0 + (z1 - z0) * b.uniform(0.55, 0.7)))
    colour = b.rng.choice(((0.8, 0.8, 0.78, 1.0), (0.05, 0.05, 0.05, 1.0), _wood_colour(b.rng)))
    _mesh_object(b, name, bm, _principled(name, colour, 0.4), role="window")


def _room_shape(b: _Build, windows: int, door: bool) -> _Room:
    w, d, h = b.uniform(4.0, 6.0), b.uniform(4.0, 7.0), b.uniform(2.5, 3.1)
    openings = []
    centres = [-w / 4, w / 4] if windows == 2 else [b.uniform(-w / 4, w / 4)] * windows
    for centre in centres:
        width = b.uniform(0.8, min(1.6, w / 2 - 0.4))
        sill = b.uniform(0.4, 1.0) if b.chance(0.8) else 0.0  # now and then a French window
        top = min(h - 0.25, sill + b.uniform(1.2, 2.2))
        openings.append((centre - width / 2, centre + width / 2, sill, top))
    door_gap = None
    if door:
        y0 = b.uniform(-d / 2 + 0.4, d / 2 - 1.4)
        door_gap = (y0, y0 + b.uniform(0.8, 0.95), b.uniform(2.0, 2.2))
    return _Room(w, d, h, b.uniform(0.12, 0.25), openings, door_gap)


def _table(b: _Build, centre: Vector, length: float, width: float, height: float,
           angle: float) -> bpy.types.Object:
    bm = bmesh.new()
    top = b.uniform(0.025, 0.05)
    _box(bm, (length, width, top), (0.0, 0.0, height - top / 2))
    round_legs = b.chance(0.5)
    leg = b.uniform(0.02, 0.035) if round_legs else b.uniform(0.04, 0.07)
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (length / 2 - 0.08), sy * (width / 2 - 0.08)
            if round_legs:
                _rod(bm, (x, y, 0.0), (x, y, height - top), leg, segments=10)
            else:
                _box(bm, (leg, leg, height - top), (x, y, (height - top) / 2))
    table = _mesh_object(b, "Table", bm, _wood(b.rng, "TableWood"), location=centre,
                         rotation=(0.0, 0.0, angle), role="thin" if round_legs else None)
    _bevel(table, 0.004, 2)
    return table


def _chair(b: _Build, name: str, location: Vector, facing: float, material) -> None:
    bm = bmesh.new()
    seat_h, size = b.uniform(0.43, 0.48), b.uniform(0.4, 0.48)
    leg = b.uniform(0.012, 0.022)
    _box(bm, (size, size, 0.035), (0.0, 0.0, seat_h))
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (size / 2 - 0.03), sy * (size / 2 - 0.03)
            top = seat_h + (0.45 if sy > 0 else 0.0)
            _rod(bm, (x + sx * 0.01, y + sy * 0.02, 0.0), (x, y, top), leg, segments=8)
    if b.chance(0.5):  # spindle back
        for k in range(b.rng.choice((3, 4, 5))):
            x = -size / 2 + 0.03 + (size - 0.06) * (k + 0.5) / 5
            _rod(bm, (x, size / 2 - 0.03, seat_h), (x, size / 2 - 0.03, seat_h + 0.42),
                 leg * 0.6, segments=6)
        _box(bm, (size, 0.025, 0.05), (0.0, size / 2 - 0.03, seat_h + 0.44))
    else:
        _box(bm, (size - 0.02, 0.02, 0.25), (0.0, size / 2 - 0.03, seat_h + 0.3))
    chair = _mesh_object(b, name, bm, material, location=location, rotation=(0, 0, facing),
                         role="thin")
    _bevel(chair, 0.003, 1)


def _shelf(b: _Build, x_wall: float, y: float, side: float, height: float) -> list[Vector]:
    """A bookshelf against the left or right wall; returns free spots on its boards."""
    length, depth = b.uniform(0.8, 1.6), b.uniform(0.25, 0.35)
    boards = b.rng.choice((3, 4, 5))
    bm = bmesh.new()
    for k in range(boards):
        _box(bm, (depth, length, 0.025), (0.0, 0.0, 0.05 + k * (height - 0.06) / (boards - 1)))
    for sy in (-1, 1):
        _box(bm, (depth, 0.025, height), (0.0, sy * length / 2, height / 2))
    x = x_wall - side * depth / 2
    material = _wood(b.rng, "ShelfWood") if b.chance(0.6) else _principled(
        "ShelfPaint", _pale(b.rng), 0.5)
    shelf = _mesh_object(b, "Shelf", bm, material, location=(x, y, 0.0))
    _bevel(shelf, 0.003, 1)
    spots = []
    for k in range(boards - 1):
        z = 0.0625 + k * (height - 0.06) / (boards - 1)
        _books(b, f"Books{k}", Vector((x, y, z)), depth, length, side)
        spots.append(Vector((x, y + b.uniform(-0.25, 0.25) * length, z)))
    return spots


def _books(b: _Build, name: str, base: Vector, depth: float, length: float, side: float) -> None:
    """A row of books of random sizes and colours, some leaning, filling part of a board."""
    y = base.y - length / 2 + 0.03 + b.uniform(0.0, 0.3) * length
    end = base.y + length / 2 - 0.03 - b.uniform(0.0, 0.4) * length
    bm = bmesh.new()
    while y < end:
        t, h = b.uniform(0.015, 0.05), b.uniform(0.16, 0.28)
        d = depth * b.uniform(0.6, 0.9)
        lean = b.uniform(-0.15, 0.15) if b.chance(0.15) else 0.0
        matrix = (Matrix.Translation((0.0, y + t / 2 - base.y, h / 2)) @
                  Matrix.Rotation(lean, 4, "X") @ Matrix.Diagonal((d, t, h, 1.0)))
        bmesh.ops.create_cube(bm, size=1.0, matrix=matrix)
        y += t + 0.002
    material = _principled(name, _vivid(b.rng), b.uniform(0.3, 0.7))
    _texturize(material, b.rng, "voronoi", b.uniform(8.0, 20.0), colour2=_vivid(b.rng))
    _mesh_object(b, name, bm, material, location=(base.x, base.y, base.z))


def _sofa(b: _Build, centre: Vector, angle: float) -> bpy.types.Object:
    length, depth = b.uniform(1.6, 2.4), b.uniform(0.8, 1.0)
    bm = bmesh.new()
    _box(bm, (length, depth, 0.42), (0.0, 0.0, 0.21))
    _box(bm, (length, 0.2, 0.42), (0.0, depth / 2 - 0.1, 0.63))
    for sx in (-1, 1):
        _box(bm, (0.18, depth, 0.22), (sx * (length / 2 - 0.09), 0.0, 0.53))
    sofa = _mesh_object(b, "Sofa", bm, _fabric(b.rng, "SofaFabric"), location=centre,
                        rotation=(0.0, 0.0, angle))
    sofa["half_length"] = length / 2
    _bevel(sofa, 0.04, 3)
    _subsurf(sofa, 1)
    return sofa


def _table_props(b: _Build, table: bpy.types.Object, top: float, length: float,
                 width: float) -> list[bpy.types.Object]:
    """Cups, vases, a bowl, a Suzanne and books on the table top."""
    props = []
    count = b.rng.randint(2, 5)
    rotation = Matrix.Rotation(table.rotation_euler.z, 3, "Z")
    for k in range(count):
        u = (k + 0.5) / count - 0.5
        local = Vector((u * length * 0.8, b.uniform(-0.3, 0.3) * width, 0.0))
        spot = Vector(table.location) + rotation @ local + Vector((0.0, 0.0, top))
        choice = b.rng.choice(("vessel", "vessel", "suzanne", "book", "glass"))
        if choice == "vessel":
            material = (_glass(b.rng, "VesselGlass") if b.chance(0.3)
                        else _principled("Ceramic", _vivid(b.rng), b.uniform(0.05, 0.4),
                                         Coat_Weight=b.rng.choice((0.0, 1.0))))
            props.append(_vessel(b, f"Vessel{k}", spot, material))
        elif choice == "glass":
            props.append(_vessel(b, f"Glass{k}", spot, _glass(b.rng, f"Glass{k}"),
                                 shape=b.rng.choice(("wineglass", "cup", "bottle"))))
        elif choice == "suzanne":
            size = b.uniform(0.15, 0.25)
            material = b.rng.choice((_metal, _plastic, _glass))(b.rng, f"Suzanne{k}")
            props.append(_suzanne(b, f"Suzanne{k}", spot + Vector((0.0, 0.0, size * 0.3)), size,
                                  material))
        else:
            bm = bmesh.new()
            for j in range(b.rng.randint(1, 4)):
                _box(bm, (b.uniform(0.15, 0.22), b.uniform(0.2, 0.28), 0.03),
                     (b.uniform(-0.01, 0.01), b.uniform(-0.01, 0.01), 0.015 + 0.03 * j))
            props.append(_mesh_object(b, f"BookStack{k}", bm,
                                      _principled(f"Book{k}", _vivid(b.rng), 0.5),
                                      location=spot, rotation=(0.0, 0.0, b.uniform(0, 3))))
    return props


def _plant(b: _Build, name: str, location: Vector) -> None:
    """A pot with a displaced ball of foliage, or a bunch of thin stems."""
    pot = bmesh.new()
    _revolve(pot, _shell_profile([(0.1, 0.0), (0.14, 0.25), (0.15, 0.28)], 0.01), segments=24)
    _mesh_object(b, name + "Pot", pot, _principled(name + "Pot", _vivid(b.rng), 0.5),
                 location=location, smooth=True)
    leaves = _principled(name + "Leaves", _hsv(b.uniform(0.22, 0.35), 0.7, b.uniform(0.05, 0.25)),
                         0.5, Sheen_Weight=0.3)
    if b.chance(0.5):
        bm = bmesh.new()
        bmesh.ops.create_icosphere(bm, subdivisions=3, radius=b.uniform(0.2, 0.35))
        crown = _mesh_object(b, name + "Foliage", bm, _random_texture(leaves, b.rng, 30.0),
                             location=location + Vector((0, 0, 0.55)), smooth=True)
        _displace(crown, b.rng, b.uniform(0.1, 0.2), b.uniform(0.05, 0.15))
    else:
        bm = bmesh.new()
        for _ in range(b.rng.randint(5, 9)):
            a = b.uniform(0, 2 * math.pi)
            lean = b.uniform(0.1, 0.4)
            tip = (lean * math.cos(a), lean * math.sin(a), b.uniform(0.5, 0.9))
            _rod(bm, (0.0, 0.0, 0.2), tip, b.uniform(0.004, 0.008), segments=6)
            _sphere(bm, b.uniform(0.03, 0.06), center=tip, segments=8, rings=4)
        _mesh_object(b, name + "Stems", bm, leaves, location=location, role="thin")


def _picture(b: _Build, name: str, location, rotation: float) -> None:
    w, h = b.uniform(0.4, 1.0), b.uniform(0.3, 0.8)
    bm = bmesh.new()
    _box(bm, (w, 0.03, h))
    frame = _mesh_object(b, name + "Frame", bm, _wood(b.rng, name + "Frame"), location=location,
                         rotation=(0, 0, rotation))
    _bevel(frame, 0.005, 1)
    bm = bmesh.new()
    _box(bm, (w - 0.06, 0.035, h - 0.06))
    canvas = _principled(name + "Canvas", _vivid(b.rng), b.uniform(0.3, 0.9))
    _random_texture(canvas, b.rng, b.uniform(2.0, 8.0), colour2=_vivid(b.rng),
                    styles=("voronoi", "wave", "noise"))
    _mesh_object(b, name + "Canvas", bm, canvas, location=location, rotation=(0, 0, rotation))


def _furnish(b: _Build, room: _Room) -> dict:
    """Furniture and props laid out in zones that do not overlap: table with chairs in the
    middle, a shelf on the left wall, a sofa on the right, lamps and plants in corners."""
    w, d = room.width, room.depth
    made: dict = {}
    angle = b.rng.choice((0.0, math.pi / 2)) + b.uniform(-0.1, 0.1)
    length, width, height = b.uniform(1.0, 1.6), b.uniform(0.7, 0.9), b.uniform(0.72, 0.76)
    if angle > 1.0:
        length = min(length, d * 0.3)
    centre = Vector((b.uniform(-0.2, 0.2) * w * 0.3, b.uniform(-0.05, 0.2) * d, 0.0))
    made["table"] = _table(b, centre, length, width, height, angle)
    b.notes["table_height"] = height
    b.notes["table_size"] = (length, width)
    # The back corners: one for a plant, the other for a floor lamp.
    b.notes["corners"] = b.rng.sample([Vector((-(w / 2 - 0.35), d / 2 - 0.4, 0.0)),
                                       Vector((w / 2 - 0.35, d / 2 - 0.4, 0.0))], 2)
    chair_material = (_wood(b.rng, "ChairWood") if b.chance(0.6)
                      else _plastic(b.rng, "ChairPlastic"))
    rotation = Matrix.Rotation(angle, 3, "Z")
    count = b.rng.randint(1, 4)
    for k in range(count):
        side = (-1, 1)[k % 2]
        # A lone chair on a side sits anywhere along it; two share the side's halves.
        shared = count - (k % 2) > 2
        along = (k // 2 - 0.5) * 0.5 * length if shared else b.uniform(-0.2, 0.2) * length
        local = Vector((along, side * (width / 2 + 0.25), 0.0))
        _chair(b, f"Chair{k}", centre + rotation @ local,
               angle + (0.0 if side < 0 else math.pi) + b.uniform(-0.3, 0.3), chair_material)
    made["props"] = _table_props(b, made["table"], height, length, width)
    made["shelf_spots"] = []
    if b.chance(0.7):
        made["shelf_spots"] = _shelf(b, -w / 2, b.uniform(-0.1, 0.3) * d, -1.0,
                                     b.uniform(1.2, min(2.2, room.height - 0.3)))
    if b.chance(0.6):
        # Along the right wall, clear of the back corner and of the camera's end of the room.
        made["sofa"] = _sofa(b, Vector((w / 2 - 0.5, 0.0, 0.0)), -math.pi / 2)
        half = made["sofa"]["half_length"]
        made["sofa"].location.y = b.uniform(min(-d / 2 + 1.2 + half, d / 2 - 0.9 - half),
                                            d / 2 - 0.9 - half)
    if b.chance(0.6):
        _plant(b, "Plant", b.notes["corners"][0])
    if b.chance(0.5):
        _picture(b, "Picture", (-w / 2 + 0.02, b.uniform(-0.3, 0.0) * d, b.uniform(1.4, 1.7)),
                 math.pi / 2)
    if b.chance(0.5):
        rug = bmesh.new()
        _box(rug, (b.uniform(1.6, 2.4), b.uniform(1.2, 1.8), 0.01), (0.0, 0.0, 0.005))
        _mesh_object(b, "Rug", rug, _fabric(b.rng, "Rug"), location=(centre.x, centre.y, 0.0),
                     rotation=(0.0, 0.0, angle))
    return made


def _interior_movers(b: _Build, made: dict) -> None:
    """One to three things that move: a ball rolling across the view, a box pushed along the
    table past the props, a prop turning, a wire ball spinning on the table."""
    camera, target = Vector(b.scene.camera.location), Vector(
        b.scene.objects["CameraTarget"].location)
    table = made["table"]
    top = Vector(table.location) + Vector((0.0, 0.0, b.notes["table_height"]))
    # Turned props look the same at every angle: only the others show a turn.
    turners = [p for p in made["props"] if not p.name.startswith(("Vessel", "Glass"))]
    for choice in b.rng.sample(["roll", "push", "spin", "wire"], b.rng.randint(1, 3)):
        if choice == "roll":
            ball = _rolling_ball(b, "Ball", (0.0, 0.0), b.uniform(0.08, 0.2),
                                 b.rng.choice((_plastic, _paint))(b.rng, "Ball"))
            _crossing(b, ball, camera, target, b.uniform(0.4, 0.7), b.uniform(0.02, 0.07))
        elif choice == "push":
            _pushed_box(b, table, top)
        elif choice == "spin" and turners:
            _spin(b, b.rng.choice(turners), b.uniform(3.0, 15.0) * b.rng.choice((-1, 1)))
        else:
            ball = _wire_ball(b, "WireBall", top + Vector((b.uniform(-0.2, 0.2), 0.0, 0.15)),
                              b.uniform(0.1, 0.15))
            _spin(b, ball, b.uniform(4.0, 20.0), axis=b.rng.choice((0, 2)))


def _pushed_box(b: _Build, table: bpy.types.Object, top: Vector) -> None:
    """A box sliding back and forth along the table top, in front of the props on it."""
    length, width = b.notes["table_size"]
    size = (b.uniform(0.12, 0.3), b.uniform(0.12, 0.25), b.uniform(0.08, 0.25))
    bm = bmesh.new()
    _box(bm, size, (0.0, 0.0, size[2] / 2))
    material = _principled("Cardboard", _hsv(0.08, 0.45, b.uniform(0.25, 0.45)), 0.85)
    _texturize(material, b.rng, "noise", 40.0, bump=0.1)
    box = _mesh_object(b, "PushedBox", bm, material, rotation=(0.0, 0.0, table.rotation_euler.z))
    _bevel(box, 0.005, 1)
    along = Matrix.Rotation(table.rotation_euler.z, 3, "Z") @ Vector((1.0, 0.0, 0.0))
    across = Matrix.Rotation(table.rotation_euler.z, 3, "Z") @ Vector((0.0, 1.0, 0.0))
    start = top + across * (width / 2 - size[1] / 2 - 0.02) * b.rng.choice((-1, 1))
    reach = max(length / 2 - size[0] / 2 - 0.02, 0.05)
    speed = b.uniform(0.02, 0.08) * b.rng.choice((-1, 1))
    _animate(b, box, lambda i: {"location": start + along * _swing(reach, speed, i)})
    box[_ROLE] = "mover"


def _interior_camera(b: _Build, room: _Room, subject: bpy.types.Object, lens_range) -> None:
    w, d = room.width, room.depth
    location = Vector((b.uniform(-0.35, 0.35) * w, -d / 2 + b.uniform(0.35, 0.9),
                       b.uniform(1.1, 1.7)))
    look = b.rng.choice(("subject", "window", "across"))
    if look == "subject":
        target = Vector(subject.location) + Vector((0.0, 0.0, 0.7))
    elif look == "window" and room.windows:
        x0, x1, z0, z1 = room.windows[0]
        target = Vector(((x0 + x1) / 2 * 0.6, d / 2, (z0 + z1) / 2 * 0.7))
    else:
        target = Vector((b.uniform(-0.4, 0.4) * w, d / 4, b.uniform(0.6, 1.2)))
    _camera(b, location, target, b.uniform(*lens_range))
    b.subject = subject
    inset = 0.3
    b.camera_bounds = (Vector((-w / 2 + inset, -d / 2 + inset, 0.3)),
                       Vector((w / 2 - inset, d / 2 - inset, room.height - inset)))
    _camera_motion(b, ("static", "pan", "dolly", "truck", "orbit", "crane"),
                   (0.2, 0.15, 0.2, 0.2, 0.15, 0.1), travel=min(w, d) * 0.2)


def _outside(b: _Build) -> None:
    """Ground outside the window, so that the sunlit view and its bounce light are right."""
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=60.0)
    ground = _principled("OutsideGround", _hsv(b.uniform(0.1, 0.3), 0.4, b.uniform(0.1, 0.3)),
                         0.9)
    _mesh_object(b, "OutsideGround", bm, ground, location=(0.0, 0.0, -0.5))


def _build_interior(b: _Build) -> None:
    """A room lit by the sun and sky through one or two windows: mostly indirect light."""
    room = _room_shape(b, windows=b.rng.choice((1, 1, 2)), door=b.chance(0.3))
    _room(b, room)
    _outside(b)
    made = _furnish(b, room)
    # The sun shines in through the back wall (its outside faces +Y).
    elevation = b.uniform(12.0, 45.0)
    azimuth = b.uniform(-35.0, 35.0)
    direction = _sun_direction(elevation, azimuth)
    _sun(b, direction, b.uniform(2.5, 6.0), _warm(b.rng), b.uniform(0.5, 3.0))
    _sky_world(b, direction, b.uniform(0.6, 1.5))
    if b.chance(0.3):  # a portal in the window guides sky sampling, as artists set up
        x0, x1, z0, z1 = room.windows[0]
        portal = _area(b, "Portal", ((x0 + x1) / 2, room.depth / 2 + room.wall, (z0 + z1) / 2),
                       ((x0 + x1) / 2, 0.0, (z0 + z1) / 2), 1.0, 1.0, (1.0, 1.0, 1.0),
                       shape="RECTANGLE")
        portal.data.size, portal.data.size_y = x1 - x0, z1 - z0
        portal.data.cycles.is_portal = True
    if b.chance(0.35):
        _area(b, "CeilingPanel", (b.uniform(-0.3, 0.3) * room.width, 0.0, room.height - 0.02),
              (0.0, 0.0, 0.0), b.uniform(0.4, 1.0), b.uniform(40.0, 200.0), _warm(b.rng))
    if b.chance(0.4):
        _room_lamp(b, room, (50.0, 500.0), (10.0, 60.0))
    if b.chance(_VOLUME_RATE["interior"]):
        # Dust in the air: sunbeams through the window become visible.
        _fog_box(b, "Dust", (0.0, 0.0, room.height / 2), (room.width, room.depth, room.height),
                 b.uniform(0.02, 0.06))
    if b.chance(0.2):
        _wall_string_lights(b, room)
    _interior_camera(b, room, made["table"], (16.0, 30.0))
    _interior_movers(b, made)


def _wall_string_lights(b: _Build, room: _Room) -> None:
    """Fairy lights hung along the left wall, between two nails."""
    x = -room.width / 2 + 0.05
    z = room.height - b.uniform(0.2, 0.5)
    y0 = b.uniform(-0.4, 0.0) * room.depth
    y1 = y0 + b.uniform(1.0, 2.5)
    _string_lights(b, "FairyLight", (x, y0, z), (x, y1, z), b.uniform(0.1, 0.35),
                   b.rng.randint(5, 12), (50.0, 500.0))


def _room_lamp(b: _Build, room: _Room, strength_range, power_range) -> dict:
    style = b.rng.choice(("floor", "table", "pendant"))
    if style == "floor":
        return _shaded_lamp(b, "FloorLamp", b.notes["corners"][1], "floor", strength_range,
                            power_range)
    if style == "table":
        table = b.scene.objects["Table"]
        spot = Vector(table.location) + Vector((b.uniform(-0.2, 0.2), b.uniform(-0.15, 0.15),
                                                b.notes["table_height"]))
        return _shaded_lamp(b, "TableLamp", spot, "table", strength_range, power_range)
    table = b.scene.objects["Table"]
    parts = _pendant(b, "Pendant", room.height, table.location.x, table.location.y,
                     b.uniform(0.5, 1.0), strength_range, power_range)
    if b.chance(0.4):
        _pendulum(b, parts["pivot"], b.uniform(1.0, 5.0), b.uniform(20.0, 60.0))
    return parts


def _build_dim_interior(b: _Build) -> None:
    """A closed room lit by one shaded lamp, or by light spilling through a door gap: little
    light, all of it bouncing, strong low-frequency noise."""
    through_door = b.chance(0.3)
    room = _room_shape(b, windows=0, door=through_door or b.chance(0.2))
    if b.chance(0.3):  # a small window at night: a little moonlight and a dark blue sky
        room = _Room(room.width, room.depth, room.height, room.wall,
                     _room_shape(b, windows=1, door=False).windows, room.door)
    _room(b, room)
    made = _furnish(b, room)
    if room.windows:
        _outside(b)
        direction = _sun_direction(b.uniform(20.0, 50.0), b.uniform(-40.0, 40.0))
        _sun(b, direction, b.uniform(0.02, 0.1), (0.6, 0.7, 1.0), b.uniform(0.5, 1.0))
        _flat_world(b, (0.02, 0.03, 0.06, 1.0), b.uniform(0.2, 1.0))
    else:
        _flat_world(b, (0.0, 0.0, 0.0, 1.0), 0.0)
    if through_door:
        # A lit hallway behind the door: an area light just outside, facing in.
        y0, y1, h = room.door
        hall = _area(b, "Hallway", (room.width / 2 + room.wall + 0.8, (y0 + y1) / 2, h * 0.8),
                     (room.width / 2, (y0 + y1) / 2, h * 0.3), b.uniform(0.5, 1.0),
                     b.uniform(30.0, 150.0), _warm(b.rng))
        _hallway(b, room)
        made["light"] = hall
    else:
        _room_lamp(b, room, (100.0, 1000.0), (15.0, 80.0))
    if b.chance(0.35):
        _candles(b, Vector(b.scene.objects["Table"].location)
                 + Vector((0.0, 0.0, b.notes["table_height"])), b.rng.randint(1, 4))
    if b.chance(0.2):
        _wall_string_lights(b, room)
    if b.chance(_VOLUME_RATE["dim_interior"]):
        _fog_box(b, "Haze", (0.0, 0.0, room.height / 2), (room.width, room.depth, room.height),
                 b.uniform(0.02, 0.08))
    _interior_camera(b, room, made["table"], (18.0, 35.0))
    _interior_movers(b, made)


def _hallway(b: _Build, room: _Room) -> None:
    """The room behind the door: walls and floor for the hallway light to bounce from."""
    y0, y1, h = room.door
    x = room.width / 2 + room.wall
    bm = bmesh.new()
    _box(bm, (2.0, 3.0, 0.1), (x + 1.0, (y0 + y1) / 2, -0.05))
    _box(bm, (2.0, 3.0, 0.1), (x + 1.0, (y0 + y1) / 2, room.height + 0.05))
    _box(bm, (0.1, 3.0, room.height), (x + 2.05, (y0 + y1) / 2, room.height / 2))
    for side in (-1, 1):
        _box(bm, (2.0, 0.1, room.height), (x + 1.0, (y0 + y1) / 2 + side * 1.55, room.height / 2))
    _mesh_object(b, "Hallway", bm, _principled("Hallway", _pale(b.rng), 0.8))


# --------------------------------------------------------------------------------------------
# Exteriors


def _ground(b: _Build, night: bool) -> None:
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=80.0)
    style = b.rng.choice(("grass", "paving", "dirt", "tiles"))
    if style == "grass":
        colour = _hsv(b.uniform(0.2, 0.3), b.uniform(0.5, 0.8), b.uniform(0.05, 0.2))
        material = _principled("Ground", colour, 0.9)
        _texturize(material, b.rng, "noise", b.uniform(0.5, 3.0), colour2=_darker(colour, 0.5),
                   roughness=(0.7, 1.0), bump=b.uniform(0.2, 0.5))
    elif style == "paving":
        colour = _hsv(b.uniform(0.05, 0.12), 0.15, b.uniform(0.2, 0.45))
        material = _principled("Ground", colour, 0.6)
        _texturize(material, b.rng, "brick", b.uniform(1.0, 3.0), colour2=_darker(colour, 0.6),
                   roughness=(0.4, 0.9), bump=0.3)
    elif style == "dirt":
        colour = _hsv(b.uniform(0.06, 0.1), 0.4, b.uniform(0.1, 0.3))
        material = _principled("Ground", colour, 0.95)
        _texturize(material, b.rng, "voronoi", b.uniform(1.0, 5.0), colour2=_darker(colour, 0.6),
                   roughness=(0.8, 1.0), bump=0.5)
    else:
        colour = _pale(b.rng)
        material = _principled("Ground", colour, 0.3)
        _texturize(material, b.rng, "checker", b.uniform(0.5, 1.0), colour2=_darker(colour, 0.4),
                   roughness=(0.1, 0.5), bump=0.05)
    if night:
        # Wet ground: the night shots artists like reflect every street lamp.
        material.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.1
    _mesh_object(b, "Ground", bm, material)


def _road(b: _Build, y: float, width: float) -> None:
    bm = bmesh.new()
    _box(bm, (120.0, width, 0.04), (0.0, y, 0.02))
    asphalt = _principled("Road", _hsv(0.0, 0.0, b.uniform(0.04, 0.1)), b.uniform(0.4, 0.8))
    _texturize(asphalt, b.rng, "noise", b.uniform(10.0, 40.0), colour2=_hsv(0.0, 0.0, 0.15),
               roughness=(0.3, 0.9), bump=0.2)
    _mesh_object(b, "Road", bm, asphalt)


def _building(b: _Build, name: str, location: Vector, night: bool) -> bpy.types.Object:
    w, d, h = b.uniform(4.0, 12.0), b.uniform(4.0, 10.0), b.uniform(4.0, 18.0)
    bm = bmesh.new()
    _box(bm, (w, d, h), (0.0, 0.0, h / 2))
    colour = _pale(b.rng)
    facade = _principled(name + "Facade", colour, b.uniform(0.5, 0.9))
    if b.chance(0.6):
        _texturize(facade, b.rng, "brick", b.uniform(2.0, 4.0), colour2=_darker(colour, 0.6),
                   roughness=(0.6, 0.95), bump=0.2)
    building = _mesh_object(b, name, bm, facade, location=location)
    building["width"] = w
    _bevel(building, 0.05, 1)
    # One window pane, arrayed over the facade that faces the street (-Y).
    columns, floors = max(1, int(w / 2.0)), max(1, int(h / 3.0))
    bm = bmesh.new()
    _box(bm, (1.0, 0.1, 1.4))
    x0 = location.x - w / 2 + w / columns / 2
    pane_location = (x0, location.y - d / 2 - 0.02, location.z + 1.6)
    if night:
        glass = _emitter(name + "Windows", (*_warm(b.rng), 1.0), b.uniform(0.5, 4.0))
    else:
        glass = _principled(name + "Windows", (0.05, 0.06, 0.07, 1.0), 0.05, Metallic=0.5)
    panes = _mesh_object(b, name + "Windows", bm, glass, location=pane_location)
    _array(panes, columns, (w / columns, 0.0, 0.0))
    _array(panes, floors, (0.0, 0.0, 3.0))
    return building


def _tree(b: _Build, name: str, location: Vector) -> None:
    height = b.uniform(2.0, 5.0)
    bm = bmesh.new()
    _cylinder(bm, b.uniform(0.1, 0.2), height, center=(0.0, 0.0, height / 2), segments=10,
              radius_top=b.uniform(0.04, 0.08))
    bark = _principled(name + "Bark", _hsv(0.07, 0.4, b.uniform(0.05, 0.15)), 0.9)
    _texturize(bark, b.rng, "wave", b.uniform(3.0, 8.0), bump=0.5)
    _mesh_object(b, name + "Trunk", bm, bark, location=location, smooth=True)
    leaves = _principled(name + "Leaves", _hsv(b.uniform(0.15, 0.33), b.uniform(0.5, 0.9),
                                               b.uniform(0.04, 0.2)), b.uniform(0.4, 0.8))
    _texturize(leaves, b.rng, "voronoi", b.uniform(5.0, 15.0),
               colour2=_hsv(b.uniform(0.12, 0.3), 0.7, 0.1), bump=0.5)
    for k in range(b.rng.randint(1, 3)):
        radius = b.uniform(0.8, 1.8)
        bm = bmesh.new()
        bmesh.ops.create_icosphere(bm, subdivisions=3, radius=radius)
        offset = Vector((b.uniform(-0.5, 0.5), b.uniform(-0.5, 0.5), height + b.uniform(-0.3, 0.8)))
        crown = _mesh_object(b, f"{name}Crown{k}", bm, leaves, location=location + offset,
                             smooth=True)
        _displace(crown, b.rng, b.uniform(0.3, 0.8), b.uniform(0.3, 0.8))


def _statue(b: _Build, location: Vector) -> bpy.types.Object:
    bm = bmesh.new()
    height = b.uniform(0.8, 1.4)
    _box(bm, (0.8, 0.8, height), (0.0, 0.0, height / 2))
    stone = _principled("Plinth", _pale(b.rng), 0.7)
    _texturize(stone, b.rng, "noise", 4.0, colour2=_pale(b.rng), roughness=(0.5, 0.9), bump=0.1)
    plinth = _mesh_object(b, "Plinth", bm, stone, location=location)
    _bevel(plinth, 0.02, 2)
    material = (_metal(b.rng, "Bronze") if b.chance(0.6) else
                _texturize(_principled("Marble", (0.8, 0.8, 0.78, 1.0), 0.2), b.rng, "wave",
                           3.0, colour2=(0.4, 0.4, 0.42, 1.0)))
    size = b.uniform(0.9, 1.4)
    return _suzanne(b, "Statue", location + Vector((0.0, 0.0, height + size * 0.35)), size,
                    material, levels=2)


def _colonnade(b: _Build, location: Vector, angle: float) -> None:
    count, spacing = b.rng.randint(3, 8), b.uniform(1.5, 3.0)
    height, radius = b.uniform(3.0, 5.0), b.uniform(0.15, 0.3)
    stone = _principled("Stone", _pale(b.rng), 0.6)
    _texturize(stone, b.rng, "noise", 3.0, colour2=_pale(b.rng), roughness=(0.5, 0.9), bump=0.15)
    bm = bmesh.new()
    _cylinder(bm, radius, height, center=(0.0, 0.0, height / 2 + 0.3), segments=16)
    pillar = _mesh_object(b, "Pillar", bm, stone, location=location, rotation=(0, 0, angle),
                          smooth=True)
    _array(pillar, count, (spacing, 0.0, 0.0))
    length = (count - 1) * spacing + 1.0
    bm = bmesh.new()
    _box(bm, (length, 1.0, 0.3), ((count - 1) * spacing / 2, 0.0, 0.15))
    _box(bm, (length, 1.0, 0.5), ((count - 1) * spacing / 2, 0.0, height + 0.55))
    beam = _mesh_object(b, "Entablature", bm, stone, location=location, rotation=(0, 0, angle))
    _bevel(beam, 0.02, 2)


def _fence(b: _Build, start: Vector, length: float, angle: float) -> None:
    """Either posts and rails or a chain-link mesh: thin geometry against the sky."""
    metal = _metal(b.rng, "FenceMetal") if b.chance(0.5) else _wood(b.rng, "FenceWood")
    if b.chance(0.5):
        bm = bmesh.new()
        bmesh.ops.create_grid(bm, x_segments=int(length / 0.1), y_segments=12,
                              size=0.5, matrix=Matrix.Diagonal((length, 1.2, 1.0, 1.0)))
        bmesh.ops.rotate(bm, verts=bm.verts, matrix=Matrix.Rotation(math.pi / 2, 3, "X"))
        mesh = _mesh_object(b, "ChainLink", bm, metal, location=start + Vector((0, 0, 0.7)),
                            rotation=(0.0, 0.0, angle))
        _wireframe(mesh, b.uniform(0.004, 0.008))
        return
    spacing = b.uniform(0.15, 0.3)
    bm = bmesh.new()
    _rod(bm, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), b.uniform(0.01, 0.025), segments=6)
    posts = _mesh_object(b, "FencePosts", bm, metal, location=start, rotation=(0, 0, angle),
                         role="thin")
    _array(posts, int(length / spacing), (spacing, 0.0, 0.0))
    bm = bmesh.new()
    for z in (0.2, 0.9):
        _rod(bm, (0.0, 0.0, z), (length, 0.0, z), 0.015, segments=6)
    _mesh_object(b, "FenceRails", bm, metal, location=start, rotation=(0, 0, angle), role="thin")


def _street_lamp(b: _Build, name: str, location: Vector, on: bool, power_scale: float
                 ) -> Vector:
    height = b.uniform(3.5, 5.0)
    bm = bmesh.new()
    _rod(bm, (0.0, 0.0, 0.0), (0.0, 0.0, height), b.uniform(0.04, 0.07), segments=10)
    _rod(bm, (0.0, 0.0, height), (0.0, 0.6, height), 0.03, segments=8)
    metal = _principled(name + "Metal", (0.03, 0.03, 0.03, 1.0), b.uniform(0.3, 0.6), Metallic=1.0)
    _mesh_object(b, name + "Pole", bm, metal, location=location, role="thin")
    head = Vector((location.x, location.y + 0.6, location.z + height - 0.15))
    bm = bmesh.new()
    _revolve(bm, _shade_profile(b, 0.22, 0.05, 0.18), segments=24, closed=True)
    _mesh_object(b, name + "Shade", bm, metal, location=head - Vector((0, 0, 0.05)), smooth=True,
                 role="lampshade")
    if on:
        _lamp_bulb(b, name, head, (200.0 * power_scale, 1000.0 * power_scale),
                   (50.0 * power_scale, 200.0 * power_scale), _warm(b.rng))
    return Vector((location.x, location.y, location.z + height))


def _car(b: _Build, location: Vector, headlights: bool) -> bpy.types.Object:
    """A car of boxes and cylinders under one empty, so it can drive as one."""
    root = _link(b, bpy.data.objects.new("Car", None))
    root.location = location
    length, width = b.uniform(3.5, 4.5), b.uniform(1.6, 1.9)
    bm = bmesh.new()
    _box(bm, (length, width, 0.6), (0.0, 0.0, 0.6))
    _box(bm, (length * 0.5, width * 0.9, 0.5), (-0.2, 0.0, 1.15))
    body = _mesh_object(b, "CarBody", bm, _paint(b.rng, "CarPaint"))
    _bevel(body, 0.08, 2)
    _subsurf(body, 1)
    bm = bmesh.new()
    for sx in (-1, 1):
        for sy in (-1, 1):
            bmesh.ops.create_cone(bm, cap_ends=True, segments=16, radius1=0.33, radius2=0.33,
                                  depth=0.22, matrix=Matrix.Translation(
                                      (sx * length * 0.32, sy * width / 2, 0.33))
                                  @ Matrix.Rotation(math.pi / 2, 4, "X"))
    wheels = _mesh_object(b, "CarWheels", bm, _principled("Tyre", (0.02, 0.02, 0.02, 1.0), 0.8),
                          smooth=True)
    parts = [body, wheels]
    if headlights:
        for sy in (-1, 1):
            bm = bmesh.new()
            _sphere(bm, 0.05, segments=8, rings=4)
            parts.append(_mesh_object(b, f"Headlight{(sy + 1) // 2}", bm,
                                      _emitter("Headlight", (1.0, 0.95, 0.85, 1.0),
                                               b.uniform(200.0, 1000.0)),
                                      location=(length / 2, sy * width * 0.35, 0.65),
                                      role="spark"))
    for part in parts:
        part.parent = root
    root[_ROLE] = "mover"
    return root


def _terrain(b: _Build) -> None:
    """Hills in the distance: a displaced grid of moderate resolution."""
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=48, y_segments=24, size=1.0,
                          matrix=Matrix.Diagonal((60.0, 20.0, 1.0, 1.0)))
    material = _principled("Hills", _hsv(b.uniform(0.2, 0.3), 0.5, b.uniform(0.05, 0.15)), 0.9)
    _texturize(material, b.rng, "noise", 0.3, colour2=_hsv(0.1, 0.3, 0.1), bump=0.3)
    hills = _mesh_object(b, "Hills", bm, material, location=(0.0, 60.0, -1.0), smooth=True)
    _displace(hills, b.rng, b.uniform(6.0, 14.0), b.uniform(8.0, 20.0))


def _street(b: _Build, night: bool) -> dict:
    """A street scene: road, buildings behind it, trees, a statue or colonnade, a fence, lamps
    with cables; the camera stands on the near side looking across."""
    made: dict = {}
    _ground(b, night)
    road_w = b.uniform(5.0, 8.0)
    road_y = road_w / 2 + b.uniform(1.5, 4.0)  # the plaza with the centrepiece is in front
    if b.chance(0.7):
        _road(b, road_y, road_w)
    far = road_y + road_w / 2 + b.uniform(2.0, 6.0)
    x = -20.0
    k = 0
    while x < 20.0:
        building = _building(b, f"Building{k}", Vector((x, far + b.uniform(3.0, 6.0), 0.0)), night)
        x += building["width"] + b.uniform(0.5, 4.0)
        k += 1
    for k in range(b.rng.randint(1, 5)):
        _tree(b, f"Tree{k}", Vector((b.uniform(-15, 15), b.rng.choice((-1, 1)) * b.uniform(0, 3)
                                     + far - 1.0, 0.0)))
    centrepiece = b.rng.choice(("statue", "colonnade", "wire"))
    spot = Vector((b.uniform(-3.0, 3.0), b.uniform(-1.0, 1.0), 0.0))
    if centrepiece == "statue":
        made["subject"] = _statue(b, spot)
    elif centrepiece == "colonnade":
        _colonnade(b, Vector((spot.x - 4.0, far - 1.5, 0.0)), 0.0)
        made["subject"] = _statue(b, spot)
    else:
        bm = bmesh.new()
        _cylinder(bm, 0.5, 1.0, center=(0.0, 0.0, 0.5), segments=24)
        _mesh_object(b, "Pedestal", bm, _principled("Pedestal", _pale(b.rng), 0.5),
                     location=spot, smooth=True)
        made["subject"] = _wire_ball(b, "Sculpture", spot + Vector((0, 0, 1.0 + 0.8)), 0.8)
        made["spinner"] = made["subject"]
    if b.chance(0.6):
        _fence(b, Vector((b.uniform(-12, -4), road_y - road_w / 2 - 0.5, 0.0)),
               b.uniform(5.0, 12.0), 0.0)
    tops = [_street_lamp(b, f"StreetLamp{k}", Vector((-8.0 + k * b.uniform(7.0, 10.0),
                                                         road_y - road_w / 2 - 0.3, 0.0)),
                         on=night, power_scale=1.0)
            for k in range(b.rng.randint(1, 3) if night else b.rng.randint(0, 2))]
    cable = _principled("CableBlack", (0.02, 0.02, 0.02, 1.0), 0.5)
    for k, (p, q) in enumerate(zip(tops, tops[1:])):
        _cable(b, f"Cable{k}", p, q, b.uniform(0.2, 0.6), b.uniform(0.005, 0.012), cable)
    if b.chance(0.5):
        _terrain(b)
    made["road"] = (road_y, road_w)
    return made


def _festoon(b: _Build, made: dict) -> None:
    """Festoon lights strung across the plaza behind the centrepiece."""
    subject = Vector(made["subject"].location)
    y = subject.y + b.uniform(1.0, 3.0)
    z = b.uniform(2.8, 3.8)
    half = b.uniform(3.0, 6.0)
    poles = bmesh.new()
    for x in (-half, half):
        _rod(poles, (subject.x + x, y, 0.0), (subject.x + x, y, z + 0.1), 0.04, segments=8)
    _mesh_object(b, "FestoonPoles", poles, _principled("FestoonPoles", _wood_colour(b.rng), 0.8),
                 role="thin")
    _string_lights(b, "Festoon", (subject.x - half, y, z), (subject.x + half, y, z),
                   b.uniform(0.3, 0.8), b.rng.randint(8, 16), (50.0, 600.0))


def _exterior_movers(b: _Build, made: dict, night: bool) -> None:
    camera = Vector(b.scene.camera.location)
    target = Vector(b.scene.objects["CameraTarget"].location)
    options = ["car", "roll", "spin", "sun"] if not night else ["car", "roll", "spin"]
    for choice in b.rng.sample(options, b.rng.randint(1, 3)):
        if choice == "car":
            road_y, _ = made["road"]
            car = _car(b, Vector((0.0, road_y + b.uniform(-1.5, 1.5), 0.0)), headlights=night)
            speed = b.uniform(0.2, 1.0) * b.rng.choice((-1, 1))  # metres per frame
            car.location.x = -speed * b.frames / 2
            car.rotation_euler.z = 0.0 if speed > 0 else math.pi
            _slide(b, car, Vector((speed, 0.0, 0.0)))
        elif choice == "roll":
            ball = _rolling_ball(b, "Ball", (0.0, 0.0), b.uniform(0.15, 0.4), _paint(b.rng, "Ball"))
            _crossing(b, ball, camera, target, b.uniform(0.3, 0.6), b.uniform(0.02, 0.08))
        elif choice == "spin":
            _spin(b, made.get("spinner") or made["subject"], b.uniform(2.0, 10.0))
        elif choice == "sun":
            sun = b.scene.objects["Sun"]
            start = Euler(sun.rotation_euler)
            step = math.radians(b.uniform(0.1, 0.5))
            _animate(b, sun, lambda i, start=start, step=step: {
                "rotation_euler": Euler((start.x + step * i, start.y, start.z))}, every_frame=False,
                     interpolation="LINEAR")


def _exterior_camera(b: _Build, subject: bpy.types.Object, lens_range) -> None:
    focus = Vector(subject.location)
    distance = b.uniform(5.0, 14.0)
    bearing = math.radians(b.uniform(-35.0, 35.0))
    location = focus + Vector((distance * math.sin(bearing), -distance * math.cos(bearing),
                               b.uniform(1.2, 3.5) - focus.z))
    target = focus + Vector((b.uniform(-1.0, 1.0), b.uniform(0.0, 3.0), b.uniform(-0.5, 1.0)))
    _camera(b, location, target, b.uniform(*lens_range))
    b.subject = subject
    _camera_motion(b, ("static", "pan", "dolly", "truck", "orbit", "crane"),
                   (0.15, 0.15, 0.2, 0.2, 0.2, 0.1), travel=6.0)


def _build_exterior(b: _Build) -> None:
    """A sunlit street with sky, buildings, trees, a statue or sculpture, sometimes fog."""
    made = _street(b, night=False)
    elevation = b.uniform(6.0, 60.0)
    direction = _sun_direction(elevation, b.uniform(0.0, 360.0))
    overcast = b.chance(0.15)
    low = elevation < 15.0
    colour = (1.0, 0.65, 0.4) if low else _warm(b.rng) if b.chance(0.5) else (1.0, 0.97, 0.92)
    sun_strength = b.uniform(0.3, 1.0) if overcast else b.uniform(2.5, 6.0)
    _sun(b, direction, sun_strength, colour, b.uniform(0.5, 3.0) * (8.0 if overcast else 1.0))
    _sky_world(b, direction, b.uniform(0.7, 1.5) * (2.0 if overcast else 1.0))
    if b.chance(_VOLUME_RATE["exterior"]):
        if b.chance(0.3):
            _haze(b, b.uniform(0.002, 0.01))
        else:
            subject = Vector(made["subject"].location)
            _fog_box(b, "Fog", subject + Vector((b.uniform(-3, 3), b.uniform(0, 4), 1.5)),
                     (b.uniform(6, 14), b.uniform(4, 10), 3.0), b.uniform(0.02, 0.3))
    if b.chance(0.15):
        _festoon(b, made)
    _exterior_camera(b, made["subject"], (22.0, 50.0))
    _exterior_movers(b, made, night=False)


def _build_night_exterior(b: _Build) -> None:
    """The same street at night: moonlight, lit windows, street lamps with small bright bulbs
    reflected in wet ground."""
    made = _street(b, night=True)
    direction = _sun_direction(b.uniform(20.0, 60.0), b.uniform(0.0, 360.0))
    _sun(b, direction, b.uniform(0.01, 0.06), (0.6, 0.7, 1.0), b.uniform(0.5, 1.0))
    _flat_world(b, (0.01, 0.015, 0.04, 1.0), b.uniform(0.3, 1.0))
    if b.chance(_VOLUME_RATE["night_exterior"]):
        subject = Vector(made["subject"].location)
        _fog_box(b, "Mist", subject + Vector((0.0, 3.0, 2.0)), (30.0, 16.0, 4.0),
                 b.uniform(0.02, 0.1))
    if b.chance(0.4):
        _festoon(b, made)
    _exterior_camera(b, made["subject"], (22.0, 50.0))
    _exterior_movers(b, made, night=True)


# --------------------------------------------------------------------------------------------
# Product shots


def _backdrop(b: _Build) -> bpy.types.Object:
    """A seamless studio sweep: a floor curving up into a wall (a bent plane)."""
    # Long enough that a long lens looking down never sees past the front edge.
    width, floor, radius, wall = 10.0, b.uniform(7.0, 9.0), b.uniform(0.8, 2.0), 4.0
    profile = [(-floor, 0.0)]
    for k in range(13):
        a = math.pi / 2 * k / 12
        profile.append((radius * math.sin(a), radius * (1.0 - math.cos(a))))
    profile.append((radius, radius + wall))
    bm = bmesh.new()
    left = [bm.verts.new((-width / 2, y + 1.0, z)) for y, z in profile]
    right = [bm.verts.new((width / 2, y + 1.0, z)) for y, z in profile]
    for k in range(len(profile) - 1):
        bm.faces.new((left[k], right[k], right[k + 1], left[k + 1]))
    style = b.rng.choice(("paper", "paper", "checker", "textured"))
    colour = _pale(b.rng) if b.chance(0.6) else _hsv(0.0, 0.0, b.uniform(0.05, 0.8))
    material = _principled("Backdrop", colour, b.uniform(0.4, 0.95))
    if style == "checker":
        _texturize(material, b.rng, "checker", b.uniform(2.0, 5.0), colour2=_darker(colour, 0.3))
    elif style == "textured":
        _random_texture(material, b.rng, b.uniform(2.0, 10.0), colour2=_darker(colour, 0.7))
    return _mesh_object(b, "Backdrop", bm, material, smooth=True)


def _product_object(b: _Build, name: str, location: Vector, choice: str) -> tuple:
    """One studio subject; returns it with its footprint radius."""
    bm = bmesh.new()
    if choice == "glass_sphere":
        r = b.uniform(0.12, 0.25)
        _sphere(bm, r, center=(0, 0, r), segments=32, rings=16)
        return _mesh_object(b, name, bm, _glass(b.rng, name), location, smooth=True), r
    if choice == "glass_vessel":
        bm.free()
        shape = b.rng.choice(("bottle", "wineglass", "vase"))
        obj = _vessel(b, name, location, _glass(b.rng, name), shape=shape, scale=2.0)
        return obj, 0.18
    if choice == "glass_block":
        s = b.uniform(0.15, 0.3)
        _box(bm, (s, s, s), (0, 0, s / 2))
        obj = _mesh_object(b, name, bm, _glass(b.rng, name, rough=b.chance(0.6)), location,
                           rotation=(0, 0, b.uniform(0, 1)))
        _bevel(obj, 0.01, 3)
        return obj, s * 0.75
    if choice == "metal_sphere":
        r = b.uniform(0.1, 0.22)
        _sphere(bm, r, center=(0, 0, r), segments=32, rings=16)
        return _mesh_object(b, name, bm, _metal(b.rng, name, brushed=False), location,
                            smooth=True), r
    if choice == "brushed_cylinder":
        r, h = b.uniform(0.08, 0.15), b.uniform(0.2, 0.45)
        _cylinder(bm, r, h, center=(0, 0, h / 2), segments=32)
        obj = _mesh_object(b, name, bm, _metal(b.rng, name, brushed=True), location, smooth=True)
        _bevel(obj, 0.005, 2)
        return obj, r
    if choice == "suzanne":
        bm.free()
        size = b.uniform(0.3, 0.45)
        material = b.rng.choice((_plastic, _paint))(b.rng, name)
        obj = _suzanne(b, name, location + Vector((0, 0, size * 0.35)), size, material, 2)
        return obj, size / 2
    if choice == "paint_blob":
        s = b.uniform(0.2, 0.35)
        _box(bm, (s * 1.6, s, s * 0.7), (0, 0, s * 0.35))
        obj = _mesh_object(b, name, bm, _paint(b.rng, name), location,
                           rotation=(0, 0, b.uniform(0, 3)))
        _bevel(obj, s * 0.15, 2)
        _subsurf(obj, 2)
        return obj, s * 0.9
    if choice == "ring":
        major = b.uniform(0.1, 0.18)
        _torus(bm, major, major * b.uniform(0.12, 0.3), center=(0, 0, 0), segments=40, sides=12)
        obj = _mesh_object(b, name, bm, _metal(b.rng, name), location + Vector((0, 0, major)),
                           rotation=(math.pi / 2, 0, b.uniform(0, 3)), smooth=True)
        return obj, major
    if choice == "wire_ball":
        bm.free()
        r = b.uniform(0.12, 0.2)
        return _wire_ball(b, name, location + Vector((0, 0, r)), r), r
    # a turned wooden or plastic piece, like a chess piece
    profile = [(0.0, 0.0), (0.08, 0.0), (0.08, 0.03), (0.04, 0.06), (0.03, 0.2), (0.06, 0.24),
               (0.05, 0.28), (0.0, 0.32)]
    scale = b.uniform(0.8, 1.4)
    _revolve(bm, [(r * scale, z * scale) for r, z in profile], segments=32)
    material = _wood(b.rng, name) if b.chance(0.5) else _plastic(b.rng, name)
    return _mesh_object(b, name, bm, material, location, smooth=True), 0.08 * scale


_PRODUCTS = ("glass_sphere", "glass_vessel", "glass_block", "metal_sphere", "brushed_cylinder",
             "suzanne", "paint_blob", "ring", "wire_ball", "turned")
_ROUND_PRODUCTS = ("glass_sphere", "glass_vessel", "metal_sphere", "brushed_cylinder", "turned")


def _build_product(b: _Build) -> None:
    """A studio shot: backdrop sweep, two or three area lights, glass, metal, plastic, paint."""
    _backdrop(b)
    turntable = None
    base_z = 0.0
    if b.chance(0.4):
        bm = bmesh.new()
        _cylinder(bm, b.uniform(0.6, 0.9), 0.06, center=(0, 0, 0.03), segments=48)
        material = (_wood(b.rng, "Turntable") if b.chance(0.5)
                    else _principled("Turntable", _pale(b.rng), 0.3))
        turntable = _mesh_object(b, "Turntable", bm, material, smooth=True)
        _bevel(turntable, 0.01, 2)
        base_z = 0.06
    count = b.rng.randint(2, 5)
    choices = b.rng.sample(_PRODUCTS, count)
    if not any(c.startswith("glass") for c in choices):
        choices[0] = b.rng.choice(("glass_sphere", "glass_vessel", "glass_block"))
    objects, radii = [], []
    for k, choice in enumerate(choices):
        obj, radius = _product_object(b, f"Product{k}", Vector((0.0, 0.0, base_z)), choice)
        objects.append(obj)
        radii.append(radius)
    span = sum(2 * r + 0.08 for r in radii)
    x = -span / 2
    for obj, radius in zip(objects, radii):
        x += radius + 0.04
        obj.location.x = x
        obj.location.y = b.uniform(-0.15, 0.15)
        x += radius + 0.04
        if turntable is not None:
            obj.parent = turntable  # the turntable sits at the origin, unrotated
    subject = objects[len(objects) // 2]
    _studio_lights(b, span)
    _product_camera(b, subject, span)
    # A turned or round object looks the same at every angle: only the others show a turn.
    turners = [o for o, c in zip(objects, choices) if c not in _ROUND_PRODUCTS]
    if turntable is not None and b.chance(0.7):
        _spin(b, turntable, b.uniform(2.0, 10.0) * b.rng.choice((-1, 1)))
    elif turners and b.chance(0.7):
        _spin(b, b.rng.choice(turners), b.uniform(3.0, 15.0))
    else:
        # A levitating product, a favourite of product animations.
        hero = b.rng.choice(objects)
        hero.location.z += b.uniform(0.1, 0.3)
        _bob(b, hero, b.uniform(0.02, 0.06), b.uniform(12.0, 40.0))
        _spin(b, hero, b.uniform(3.0, 15.0))
    if b.chance(0.35):
        passer = _rolling_ball(b, "Passer", (0.0, 0.0), b.uniform(0.05, 0.12),
                               b.rng.choice((_plastic, _metal))(b.rng, "Passer"))
        _crossing(b, passer, Vector(b.scene.camera.location),
                  Vector(b.scene.objects["CameraTarget"].location), b.uniform(0.3, 0.6),
                  b.uniform(0.02, 0.06))
    if b.chance(_VOLUME_RATE["product"]):
        _fog_box(b, "StudioHaze", (0.0, 0.5, 1.5), (6.0, 5.0, 3.0), b.uniform(0.02, 0.08))


def _studio_lights(b: _Build, span: float) -> None:
    centre = Vector((0.0, 0.0, 0.2))
    key_side = b.rng.choice((-1, 1))
    key_colour = _warm(b.rng) if b.chance(0.3) else (1.0, 1.0, 1.0)
    key = _area(b, "Key", (key_side * b.uniform(1.0, 2.5), -b.uniform(1.0, 2.5),
                           b.uniform(1.2, 2.5)),
                centre, b.uniform(0.4, 1.5), b.uniform(50.0, 200.0), key_colour,
                shape=b.rng.choice(("SQUARE", "RECTANGLE", "DISK")))
    _area(b, "Fill", (-key_side * b.uniform(1.5, 3.0), -b.uniform(0.5, 2.0), b.uniform(0.8, 1.8)),
          centre, b.uniform(1.0, 2.5), b.uniform(15.0, 60.0), (0.9, 0.95, 1.0))
    if b.chance(0.7):
        _area(b, "Rim", (b.uniform(-1.0, 1.0), b.uniform(1.0, 2.0), b.uniform(1.5, 3.0)),
              centre, b.uniform(0.3, 1.0), b.uniform(30.0, 150.0), (1.0, 1.0, 1.0))
    if b.chance(0.45):  # a tiny very bright light: sparkles on metal, caustics through glass
        spot = Vector((b.uniform(-1.0, 1.0) * span, b.uniform(0.3, 1.5), b.uniform(0.5, 1.5)))
        # A practical on a thin stand: a bare LED or a point light of tiny radius.
        stand = bmesh.new()
        _rod(stand, (spot.x, spot.y, 0.0), (spot.x, spot.y, spot.z - 0.03), 0.004, segments=6)
        _mesh_object(b, "SparkStand", stand, _metal(b.rng, "SparkStand"), role="thin")
        if b.chance(0.5):
            _point(b, "Spark", spot, b.uniform(5.0, 40.0), b.uniform(0.0, 0.02), (1.0, 0.95, 0.9),
                   role="spark")
        else:
            _tiny_light(b, "Spark", spot, b.uniform(0.01, 0.025), (1.0, 0.95, 0.9, 1.0),
                        b.uniform(300.0, 1000.0))
    if b.chance(0.4):
        _animate(b, key, _orbit_pose(key, centre, math.radians(b.uniform(0.3, 1.5))))
    _flat_world(b, _hsv(0.6, 0.1, 1.0), b.uniform(0.0, 0.15))


def _orbit_pose(obj: bpy.types.Object, centre: Vector, step: float) -> Callable[[int], dict]:
    offset = Vector(obj.location) - centre

    def pose(i: int) -> dict:
        location = centre + Matrix.Rotation(step * i, 3, "Z") @ offset
        return {"location": location,
                "rotation_euler": (centre - location).to_track_quat("-Z", "Y").to_euler()}

    return pose


def _product_camera(b: _Build, subject: bpy.types.Object, span: float) -> None:
    lens = b.uniform(40.0, 100.0)
    # Far enough that the row of objects fills most of the frame width.
    distance = max(span, 0.5) * 1.3 / (2.0 * math.tan(math.atan(18.0 / lens)))
    elevation = math.radians(b.uniform(5.0, 30.0))
    bearing = math.radians(b.uniform(-25.0, 25.0))
    target = Vector((0.0, 0.0, b.uniform(0.1, 0.25)))
    location = target + distance * Vector((math.sin(bearing) * math.cos(elevation),
                                           -math.cos(bearing) * math.cos(elevation),
                                           math.sin(elevation)))
    _camera(b, location, target, lens)
    b.subject = subject
    _camera_motion(b, ("static", "pan", "dolly", "truck", "orbit", "crane"),
                   (0.25, 0.1, 0.2, 0.15, 0.2, 0.1), travel=distance * 0.3)


_BUILDERS: dict[str, Callable[[_Build], None]] = {
    "interior": _build_interior,
    "dim_interior": _build_dim_interior,
    "exterior": _build_exterior,
    "product": _build_product,
    "night_exterior": _build_night_exterior,
}


# --------------------------------------------------------------------------------------------
# Reading a scene back (describe)


def _object_materials(obj: bpy.types.Object) -> list[bpy.types.Material]:
    data = getattr(obj, "data", None)
    return [m for m in getattr(data, "materials", ()) if m is not None]


def _input_value(material: bpy.types.Material, name: str, default: float) -> float:
    tree = material.node_tree
    node = tree.nodes.get("Principled BSDF") if tree else None
    if node is None or name not in node.inputs:
        return default
    return float(node.inputs[name].default_value)


def _has_volume(tree) -> bool:
    if tree is None:
        return False
    return any(n.bl_idname in ("ShaderNodeOutputMaterial", "ShaderNodeOutputWorld")
               and n.inputs["Volume"].is_linked for n in tree.nodes)


def _pure_emitter(obj: bpy.types.Object) -> bool:
    materials = _object_materials(obj) if obj.type == "MESH" else []
    return bool(materials) and all(m.node_tree and m.node_tree.nodes.get("Emission") is not None
                                   and m.node_tree.nodes.get("Principled BSDF") is None
                                   for m in materials)


def _is_animated(obj: bpy.types.Object) -> bool:
    chain = obj
    while chain is not None:
        if chain.animation_data and chain.animation_data.action:
            return True
        if any(c.type == "TRACK_TO" and c.target and _is_animated(c.target)
               for c in chain.constraints):
            return True
        chain = chain.parent
    return False


def _describe_light(obj: bpy.types.Object) -> dict:
    data = obj.data
    info = {"name": obj.name, "type": data.type, "energy": round(float(data.energy), 4),
            "color": [round(c, 4) for c in data.color], "role": obj.get(_ROLE, ""),
            "moves": _is_animated(obj)}
    if data.type == "SUN":
        info["angle_deg"] = round(math.degrees(data.angle), 3)
    elif data.type == "AREA":
        info["size"] = [round(data.size, 4), round(data.size_y, 4)]
        info["portal"] = bool(data.cycles.is_portal)
    else:
        info["radius"] = round(float(data.shadow_soft_size), 4)
    return info


def _describe_emitter(obj: bpy.types.Object) -> dict:
    node = _object_materials(obj)[0].node_tree.nodes["Emission"]
    return {"name": obj.name, "strength": round(float(node.inputs["Strength"].default_value), 3),
            "size": round(max(obj.dimensions), 4), "role": obj.get(_ROLE, ""),
            "moves": _is_animated(obj)}


def _describe_camera(scene: bpy.types.Scene) -> dict:
    camera = scene.camera
    if camera is None:
        return {}
    dof = camera.data.dof
    return {"lens_mm": round(camera.data.lens, 3),
            "motion": scene.get("affinity_camera_motion", ""),
            "fstop": round(dof.aperture_fstop, 3) if dof.use_dof else None,
            "shutter": round(scene.render.motion_blur_shutter, 3)
            if scene.render.use_motion_blur else None}
