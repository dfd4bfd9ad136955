"""Affinity Denoiser: Cycles animations denoised from per-sample features, temporally stable.

The native core (the ``affinity_core`` module) is imported lazily, when a denoise-render starts; a
missing core is reported there and in the panel, and does not stop the add-on from loading.
"""

from __future__ import annotations

from . import engine, operators, properties, render_engine, ui

_modules = (properties, engine, render_engine, operators, ui)


def register() -> None:
    for module in _modules:
        module.register()


def unregister() -> None:
    for module in reversed(_modules):
        module.unregister()
