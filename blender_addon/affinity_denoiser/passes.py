"""Which Cycles passes the feature schema needs, turning them on, and reading them per sample.

Pass names changed across Blender versions (``DiffDir`` became ``Diffuse Direct``), so each
pass is known by a role and resolved against the names a render result actually has.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import numpy as np

from .overrides import Overrides

#: Shader AOV written by materials.py: view distance of the first camera hit.
AOV_DISTANCE = "affinity_distance"
#: Shader AOV written by materials.py: (roughness, metallic, transmission) of the first hit.
AOV_SURFACE = "affinity_surface"
#: Shader AOV written by materials.py: Object Info "Random" of the first hit (names its object).
AOV_OBJECT = "affinity_object"
#: Shader AOV written by materials.py: the first hit's position in its object's space.
AOV_LOCAL = "affinity_local"
#: The AOVs materials.py writes, with their view layer AOV types.
SHADER_AOVS = ((AOV_DISTANCE, "VALUE"), (AOV_SURFACE, "COLOR"), (AOV_OBJECT, "VALUE"),
               (AOV_LOCAL, "COLOR"))

#: role -> the names that role's pass had in the Blender versions we know, newest first.
PASS_NAMES: dict[str, tuple[str, ...]] = {
    "combined": ("Combined",),
    "depth": ("Depth", "Z"),
    "diffuse_direct": ("Diffuse Direct", "DiffDir"),
    "diffuse_indirect": ("Diffuse Indirect", "DiffInd"),
    "diffuse_color": ("Diffuse Color", "DiffCol"),
    "emission": ("Emission", "Emit"),
    "denoising_normal": ("Denoising Normal",),
    "denoising_albedo": ("Denoising Albedo",),
    "denoising_depth": ("Denoising Depth",),
    "aov_distance": (AOV_DISTANCE,),
    "aov_surface": (AOV_SURFACE,),
    "aov_object": (AOV_OBJECT,),
    "aov_local": (AOV_LOCAL,),
}
#: Roles that may be missing from a result (older Cycles); features.py has a fallback.
OPTIONAL_ROLES = frozenset({"denoising_depth"})

#: View layer switches for the passes above (view_layer.<name>, view_layer.cycles.<name>).
_VIEW_LAYER_PASSES = (
    "use_pass_combined",
    "use_pass_z",
    "use_pass_diffuse_direct",
    "use_pass_diffuse_indirect",
    "use_pass_diffuse_color",
    "use_pass_emit",
)
_CYCLES_VIEW_LAYER_PASSES = ("denoising_store_passes",)


class PassError(RuntimeError):
    """A pass the feature schema needs is not in the render result."""


def enable_passes(overrides: Overrides, view_layer: Any) -> None:
    """Turns on the passes the features need (the user's settings come back with overrides)."""
    for name in _VIEW_LAYER_PASSES:
        overrides.set(view_layer, name, True)
    for name in _CYCLES_VIEW_LAYER_PASSES:
        overrides.set(view_layer.cycles, name, True)


@contextlib.contextmanager
def shader_aovs(view_layer: Any) -> Iterator[None]:
    """Adds the view layer AOVs that materials.py writes, and removes exactly those again.

    An AOV of the same name that the user already has is used as it is and left in place.
    """
    existing = {aov.name: aov for aov in view_layer.aovs}
    added = []
    try:
        for name, kind in SHADER_AOVS:
            if name in existing:
                if existing[name].type != kind:
                    raise PassError(f"the view layer has an AOV '{name}' of type "
                                    f"{existing[name].type}; rename it (we need {kind})")
                continue
            aov = view_layer.aovs.add()
            aov.name = name
            aov.type = kind
            added.append(name)
        yield
    finally:
        for name in added:
            for aov in view_layer.aovs:
                if aov.name == name:
                    view_layer.aovs.remove(aov)
                    break


def read_result(result: Any) -> dict[str, np.ndarray]:
    """Every pass of the first layer of a render result as float32 (H, W, C), top row first.

    Blender stores rows bottom-up; the arrays are flipped views of the copied buffers.
    ``foreach_get`` into a preallocated array is fast (far faster than converting ``rect``
    element by element).
    """
    width, height = result.resolution_x, result.resolution_y
    layer = result.layers[0]
    passes = {}
    for render_pass in layer.passes:
        buffer = np.empty(width * height * render_pass.channels, dtype=np.float32)
        render_pass.rect.foreach_get(buffer)
        passes[render_pass.name] = buffer.reshape(height, width, render_pass.channels)[::-1]
    return passes


def resolve(names: Any) -> dict[str, str]:
    """Maps each role to the pass name present in ``names`` (an iterable of pass names)."""
    present = set(names)
    resolved = {}
    for role, candidates in PASS_NAMES.items():
        found = next((c for c in candidates if c in present), None)
        if found is not None:
            resolved[role] = found
        elif role not in OPTIONAL_ROLES:
            raise PassError(
                f"the render result has no '{candidates[0]}' pass (role {role}); "
                f"it has: {', '.join(sorted(present))}"
            )
    return resolved


def by_role(passes: dict[str, np.ndarray], names: dict[str, str]) -> dict[str, np.ndarray]:
    """The passes of one sample keyed by role (see ``resolve``)."""
    return {role: passes[name] for role, name in names.items()}
