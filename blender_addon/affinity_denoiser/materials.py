"""Temporary shader AOV outputs in the user's materials, removed again without a trace.

Each material gets an AOV output with the view distance of the shading point (per-sample depth:
Cycles' Z pass is only written for the sample at offset 0), one with the surface's
(roughness, metallic, transmission), read from the BSDF nodes that feed the active material
output, and two for motion.py: the shading point in object space (Texture Coordinate "Object")
and the Object Info "Random" value, which tells which object or instance was hit. Everything
added is named with a prefix and removed in a ``finally``; the tests compare a snapshot of
every material before and after.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

from . import passes

NODE_PREFIX = "affinity_tmp_"
#: How deep Mix/Add shader chains are followed; deeper parts count as diffuse.
MAX_SHADER_DEPTH = 8

# A value is a constant float or an output socket carrying a float.
Value = float | Any

#: (roughness, metallic, transmission) of BSDF nodes that have no such inputs.
_FIXED_SURFACES = {
    "BSDF_DIFFUSE": (1.0, 0.0, 0.0),
    "BSDF_TRANSLUCENT": (1.0, 0.0, 0.0),
    "SUBSURFACE_SCATTERING": (1.0, 0.0, 0.0),
    "BSDF_SHEEN": (1.0, 0.0, 0.0),
    "BSDF_VELVET": (1.0, 0.0, 0.0),
    "EMISSION": (1.0, 0.0, 0.0),
    "BSDF_TRANSPARENT": (0.0, 0.0, 1.0),
    "HOLDOUT": (1.0, 0.0, 0.0),
}
#: BSDF nodes with a Roughness input, and their (metallic, transmission) flags.
_ROUGH_SURFACES = {
    "BSDF_GLOSSY": (1.0, 0.0),
    "BSDF_ANISOTROPIC": (1.0, 0.0),
    "BSDF_METALLIC": (1.0, 0.0),
    "BSDF_GLASS": (0.0, 1.0),
    "BSDF_REFRACTION": (0.0, 1.0),
    "BSDF_TOON": (0.0, 0.0),
}


def editable_materials(data: Any) -> list[Any]:
    """Materials whose node trees we may change for a render (local, with nodes)."""
    return [
        m
        for m in data.materials
        if m.node_tree is not None and m.library is None and not m.is_grease_pencil
    ]


class _Builder:
    """Adds nodes to one material's tree, remembering their names."""

    def __init__(self, tree: Any, added: list[str]) -> None:
        self.tree = tree
        self.added = added

    def node(self, kind: str) -> Any:
        node = self.tree.nodes.new(kind)
        self.added.append(node.name)
        node.name = f"{NODE_PREFIX}{len(self.added)}"
        self.added[-1] = node.name  # Blender appends .001 when the name is taken
        node.label = "affinity (temporary)"
        node.select = False
        return node

    def connect(self, value: Value, target: Any) -> None:
        if isinstance(value, float):
            target.default_value = value
        else:
            self.tree.links.new(value, target)

    def math(self, operation: str, *values: Value) -> Value:
        if all(isinstance(v, float) for v in values):
            a, b, *rest = values
            if operation == "SUBTRACT":
                return a - b
            if operation == "MAXIMUM":
                return max(a, b)
            if operation == "MULTIPLY_ADD":
                return a * b + rest[0]
        node = self.node("ShaderNodeMath")
        node.operation = operation
        for value, socket in zip(values, node.inputs):
            self.connect(value, socket)
        return node.outputs[0]

    def mix(self, factor: Value, a: Value, b: Value) -> Value:
        """a + factor * (b - a), as Cycles' Mix Shader weighs its two inputs."""
        return self.math("MULTIPLY_ADD", factor, self.math("SUBTRACT", b, a), a)


def _input_value(node: Any, names: tuple[str, ...], default: float) -> Value:
    """The float an input carries: the linked output socket, or its constant value."""
    for name in names:
        socket = node.inputs.get(name)
        if socket is None:
            continue
        if socket.is_linked and socket.links and not socket.links[0].is_muted:
            return socket.links[0].from_socket
        value = socket.default_value
        return float(value if isinstance(value, (int, float)) else value[0])
    return default


def _linked_node(socket: Any) -> Any:
    if not socket.is_linked or not socket.links or socket.links[0].is_muted:
        return None
    node = socket.links[0].from_node
    while node is not None and node.type == "REROUTE":
        node = _linked_node(node.inputs[0])
    return node


def _surface(builder: _Builder, node: Any, depth: int) -> tuple[Value, Value, Value]:
    """(roughness, metallic, transmission) of the shader a node outputs."""
    if node is None or node.mute or depth > MAX_SHADER_DEPTH:
        return (1.0, 0.0, 0.0)
    kind = node.type
    if kind == "BSDF_PRINCIPLED":
        return (
            _input_value(node, ("Roughness",), 0.5),
            _input_value(node, ("Metallic",), 0.0),
            _input_value(node, ("Transmission Weight", "Transmission"), 0.0),
        )
    if kind in _ROUGH_SURFACES:
        metallic, transmission = _ROUGH_SURFACES[kind]
        return (_input_value(node, ("Roughness",), 0.5), metallic, transmission)
    if kind in _FIXED_SURFACES:
        return _FIXED_SURFACES[kind]
    if kind == "MIX_SHADER":
        factor = _input_value(node, ("Fac", "Factor"), 0.5)
        a = _surface(builder, _linked_node(node.inputs[1]), depth + 1)
        b = _surface(builder, _linked_node(node.inputs[2]), depth + 1)
        return tuple(builder.mix(factor, x, y) for x, y in zip(a, b))  # type: ignore[return-value]
    if kind == "ADD_SHADER":
        a = _surface(builder, _linked_node(node.inputs[0]), depth + 1)
        b = _surface(builder, _linked_node(node.inputs[1]), depth + 1)
        return tuple(builder.math("MAXIMUM", x, y) for x, y in zip(a, b))  # type: ignore[return-value]
    return (1.0, 0.0, 0.0)


def _add_outputs(material: Any, added: list[str]) -> None:
    """Adds the AOV output nodes, appending each new node's name to ``added`` at once."""
    tree = material.node_tree
    builder = _Builder(tree, added)
    camera = builder.node("ShaderNodeCameraData")
    distance_out = builder.node("ShaderNodeOutputAOV")
    distance_out.aov_name = passes.AOV_DISTANCE
    tree.links.new(camera.outputs["View Distance"], distance_out.inputs["Value"])

    output = tree.get_output_node("CYCLES")
    shader = _linked_node(output.inputs["Surface"]) if output is not None else None
    roughness, metallic, transmission = _surface(builder, shader, 0)
    combine = builder.node("ShaderNodeCombineXYZ")
    for value, socket in zip((roughness, metallic, transmission), combine.inputs):
        builder.connect(value, socket)
    surface_out = builder.node("ShaderNodeOutputAOV")
    surface_out.aov_name = passes.AOV_SURFACE
    tree.links.new(combine.outputs[0], surface_out.inputs["Color"])

    info = builder.node("ShaderNodeObjectInfo")
    object_out = builder.node("ShaderNodeOutputAOV")
    object_out.aov_name = passes.AOV_OBJECT
    tree.links.new(info.outputs["Random"], object_out.inputs["Value"])
    coordinates = builder.node("ShaderNodeTexCoord")  # its object is None: the hit object's own
    local_out = builder.node("ShaderNodeOutputAOV")
    local_out.aov_name = passes.AOV_LOCAL
    tree.links.new(coordinates.outputs["Object"], local_out.inputs["Color"])


def _remove(material: Any, names: list[str]) -> None:
    nodes = material.node_tree.nodes
    for name in reversed(names):
        node = nodes.get(name)
        if node is not None:
            nodes.remove(node)


@contextlib.contextmanager
def surface_aovs(data: Any) -> Iterator[int]:
    """Adds the AOV outputs to every editable material; yields how many were changed.

    The added nodes (and with them their links) are removed on leaving the block, whatever
    happens inside it; the active node of each tree is put back.
    """
    added: list[tuple[Any, list[str], Any]] = []
    try:
        for material in editable_materials(data):
            names: list[str] = []
            # Registered before adding, so a failure half-way still removes what was added.
            added.append((material, names, material.node_tree.nodes.active))
            _add_outputs(material, names)
        yield len(added)
    finally:
        for material, names, active in added:
            _remove(material, names)
            material.node_tree.nodes.active = active
