"""The compositor side: the user's graph runs on the denoised frame.

During a denoise-render the pipeline *presents* each denoised frame through the capture engine
(engine.py): the Render Layers node then outputs the denoised image as "Image" (and the mean of
the samples for every other pass), Blender runs the user's compositing graph on it and the result
is saved in the scene's output format. Afterwards an Image node named ``Affinity Denoised``
in the compositing graph points at the sequence of denoised EXR files, so the graph can be
re-run on them later without rendering again. Blender 5.3 keeps the graph as the node group of
the active entry of ``scene.compositor_effects`` (``scene.compositing_node_group``, which says
the same, warns that it goes in Blender 6), Blender 5.0 in ``scene.compositing_node_group``,
earlier versions in ``scene.node_tree`` (with ``use_nodes``).
"""

from __future__ import annotations

import os
from typing import Any

NODE_NAME = "Affinity Denoised"


def compositing_tree(scene: Any) -> Any:
    """The scene's compositing node tree, or None when it has none."""
    effects = getattr(scene, "compositor_effects", None)
    if effects is not None:
        effect = effects.active
        return effect.node_group if effect is not None else None
    if hasattr(scene, "compositing_node_group"):
        return scene.compositing_node_group
    if getattr(scene, "use_nodes", False):
        return scene.node_tree
    return None


def update_denoised_node(scene: Any, first_file: str, first_frame: int, frame_count: int) -> Any:
    """Points the ``Affinity Denoised`` Image node at a denoised sequence (created if needed).

    Returns the node, or None when the scene has no compositing graph (nothing is created).
    ``first_file`` is the denoised EXR of ``first_frame``; Blender finds the others by number.
    """
    import bpy

    tree = compositing_tree(scene)
    if tree is None:
        return None
    node = tree.nodes.get(NODE_NAME)
    if node is None or node.type != "IMAGE":
        node = tree.nodes.new("CompositorNodeImage")
        node.name = NODE_NAME
        node.label = NODE_NAME
        node.location = (-400.0, -400.0)
    image = bpy.data.images.load(os.path.abspath(first_file), check_existing=True)
    image.source = "SEQUENCE" if frame_count > 1 else "FILE"
    image.colorspace_settings.name = "Non-Color"
    node.image = image
    # Scene frame f shows file number f: number = f - frame_start + 1 + frame_offset.
    node.frame_start = first_frame
    node.frame_offset = first_frame - 1
    node.frame_duration = frame_count
    return node
