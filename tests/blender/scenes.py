"""Tiny Cycles scenes built in code for the Blender tests."""

from __future__ import annotations

import math

import bpy

WIDTH, HEIGHT, FRAMES, SPP = 64, 48, 3, 4


def _principled(name: str, **inputs: object) -> bpy.types.Material:
    material = bpy.data.materials.new(name)
    if material.node_tree is None:  # Blender < 5 creates the node tree on request
        material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    for socket, value in inputs.items():
        bsdf.inputs[socket.replace("_", " ")].default_value = value
    return material


def _add(primitive: str, material: bpy.types.Material, **kwargs: object) -> bpy.types.Object:
    getattr(bpy.ops.mesh, primitive)(**kwargs)
    obj = bpy.context.object
    obj.data.materials.append(material)
    return obj


def build_scene(width: int = WIDTH, height: int = HEIGHT, frames: int = FRAMES,
                spp: int = SPP, threads: int = 2) -> bpy.types.Scene:
    """A floor, a glossy metal sphere, a glass sphere, an emissive cube, a pure emitter and a
    point light, seen by a camera that moves and turns a little every frame."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    render = scene.render
    render.engine = "CYCLES"
    render.resolution_x, render.resolution_y, render.resolution_percentage = width, height, 100
    render.threads_mode = "FIXED"
    render.threads = threads
    scene.cycles.device = "CPU"
    scene.cycles.samples = spp
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.frame_start, scene.frame_end = 1, frames

    world = bpy.data.worlds.new("World")
    scene.world = world
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[0].default_value = (0.05, 0.07, 0.1, 1.0)

    _add("primitive_plane_add", _principled("Floor", Base_Color=(0.8, 0.6, 0.4, 1.0),
                                            Roughness=1.0), size=20)
    _add("primitive_uv_sphere_add", _principled("Metal", Base_Color=(0.9, 0.9, 0.9, 1.0),
                                                Metallic=1.0, Roughness=0.2),
         radius=1.0, location=(-1.5, 0.0, 1.0), segments=16, ring_count=8)
    _add("primitive_uv_sphere_add", _principled("Glass", Transmission_Weight=1.0,
                                                Roughness=0.0, IOR=1.5),
         radius=1.0, location=(1.2, -0.5, 1.0), segments=16, ring_count=8)
    _add("primitive_cube_add", _principled("Emissive", Emission_Color=(1.0, 0.8, 0.5, 1.0),
                                           Emission_Strength=5.0),
         size=0.6, location=(0.0, 2.0, 0.3))
    emitter = bpy.data.materials.new("PureEmitter")
    if emitter.node_tree is None:
        emitter.use_nodes = True
    tree = emitter.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 3.0
    tree.links.new(emission.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    _add("primitive_cube_add", emitter, size=0.5, location=(-0.3, -2.5, 0.25))

    bpy.ops.object.light_add(type="POINT", location=(2.0, -2.0, 5.0))
    bpy.context.object.data.energy = 800.0

    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    for i in range(frames):
        camera.location = (0.3 * i, -7.0, 3.0 + 0.1 * i)
        camera.rotation_euler = (math.radians(70.0), 0.0, math.radians(2.0 * i))
        camera.keyframe_insert("location", frame=1 + i)
        camera.keyframe_insert("rotation_euler", frame=1 + i)
    scene.frame_set(1)
    return scene


def add_exposure_compositor(scene: bpy.types.Scene, exposure: float) -> None:
    """A compositing graph: Render Layers -> Exposure (x 2^exposure) -> the output."""
    # Blender 5: a node group of the scene, in 5.3 that of a compositor effect (reading
    # scene.compositing_node_group there warns that it goes in Blender 6).
    blender5 = hasattr(scene, "compositor_effects") or hasattr(scene, "compositing_node_group")
    if blender5:
        tree = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
        tree.interface.new_socket(name="Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        if hasattr(scene, "compositor_effects"):
            scene.compositor_effects.new("Compositing").node_group = tree
        else:
            scene.compositing_node_group = tree
        result = tree.nodes.new("NodeGroupOutput")
    else:
        scene.use_nodes = True
        tree = scene.node_tree
        tree.nodes.clear()
        result = tree.nodes.new("CompositorNodeComposite")
    layers = tree.nodes.new("CompositorNodeRLayers")
    node = tree.nodes.new("CompositorNodeExposure")
    node.inputs["Exposure"].default_value = exposure
    tree.links.new(layers.outputs["Image"], node.inputs["Image"])
    tree.links.new(node.outputs["Image"], result.inputs[0])
    scene.render.use_compositing = True


def use_float_exr_output(scene: bpy.types.Scene) -> None:
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    settings.color_mode = "RGBA"


def read_image(path: str) -> object:
    """An image file's pixels as float32 (H, W, 4), top row first, no colour conversion."""
    import numpy as np

    image = bpy.data.images.load(path)
    try:
        image.colorspace_settings.name = "Non-Color"
        pixels = np.empty(image.size[0] * image.size[1] * 4, np.float32)
        image.pixels.foreach_get(pixels)
        return pixels.reshape(image.size[1], image.size[0], 4)[::-1].copy()
    finally:
        bpy.data.images.remove(image)
