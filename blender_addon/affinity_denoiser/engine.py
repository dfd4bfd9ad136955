"""A render engine that is Cycles, plus in-memory access to the finished render result.

In background mode ``bpy.data.images['Render Result']`` has no pixels, and writing a
multilayer EXR per sub-render and reading it back is slower (docs/BLENDER.md, "Reading
passes"). An engine that runs Cycles' own engine code can read every pass of its result right
after Cycles finishes a frame. The same engine can also *present* a frame: instead of
rendering, it fills the render result with given passes (the denoised image as Combined), so
that Blender's compositor and file output run on the denoised frame.

The pipeline switches the scene to this engine for the duration of a denoise-render only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

#: The capture engine (internal: sub-renders and presenting a denoised frame).
IDNAME = "AFFINITY_DENOISER_CYCLES"
#: The engine users choose, "Cycles + Affinity Denoiser" (render_engine.py).
DENOISING_ENGINE = "AFFINITY_DENOISER"

_engine_class: type | None = None


class _Session:
    """What the next render should do: capture into ``sink`` or present ``frame``."""

    def __init__(self) -> None:
        self.sink: Callable[[Any], None] | None = None
        self.present: dict[str, np.ndarray] | None = None


session = _Session()

T = TypeVar("T")


def render_and_capture(read: Callable[[Any], T], scene: str = "", layer: str = "") -> tuple[T | None, float]:
    """Renders the scene once (``bpy.ops.render.render``, the scene's engine set to this one)
    and returns what ``read`` made of the finished render result, or None when the render was
    cancelled, and the render's wall seconds. ``scene`` and ``layer`` name what to render where
    the context does not (a background process has no window)."""
    import bpy

    captured: list[T] = []
    session.sink = lambda result: captured.append(read(result))
    start = time.perf_counter()
    try:
        bpy.ops.render.render(scene=scene, layer=layer)
    finally:
        session.sink = None
    return (captured[0] if captured else None), time.perf_counter() - start


def write_result(engine: Any, width: int, height: int, frame: dict[str, np.ndarray],
                 layer: str = "") -> None:
    """Fills ``engine``'s render result (of view layer ``layer``; the one being rendered when
    empty) with the images of ``frame`` by pass name, bottom row first as Blender wants;
    passes ``frame`` lacks are zero."""
    result = engine.begin_result(0, 0, width, height, layer=layer)
    try:
        fill_passes(result, frame, width, height)
    finally:
        engine.end_result(result)


def fill_passes(result: Any, images: dict[str, np.ndarray], width: int, height: int) -> None:
    """Sets each pass of ``result``'s first layer to the image of its name (top row first, its
    first channels), bottom row first as Blender wants; a missing or misfitting one is zero."""
    for render_pass in result.layers[0].passes:
        channels = render_pass.channels
        image = images.get(render_pass.name)
        if image is not None:
            image = image[..., :channels]
        if image is None or image.shape != (height, width, channels):
            image = np.zeros((height, width, channels), np.float32)
        render_pass.rect.foreach_set(np.ascontiguousarray(image[::-1], np.float32).ravel())


#: What Cycles' engine class holds besides its methods; everything else of it is copied.
_NOT_COPIED = {"__module__", "__qualname__", "__doc__", "__dict__", "__weakref__", "__init__",
               "bl_idname", "bl_label", "bl_rna"}


def cycles_namespace() -> dict[str, Any]:
    """Cycles' engine methods and ``bl_use_*`` flags, for an engine class that runs Cycles' own
    engine code with hooks around it.

    Such a class is *not* a subclass of ``cycles.CyclesRender``: registering a subclass of a
    registered class takes the base class off its RNA type (Blender's ``pyrna_register_class``),
    after which every call into the real Cycles engine failed with "unable to get Python class
    for RNA struct 'CYCLES'" and plain Cycles renders came out black, even after unregistering.
    Instead it derives from ``bpy.types.RenderEngine`` and copies these; they call
    ``cycles.engine`` with the engine instance, whatever its class."""
    import cycles  # Blender's bundled Cycles add-on

    namespace: dict[str, Any] = {}
    for name, value in vars(cycles.CyclesRender).items():
        if name in _NOT_COPIED:
            continue
        if callable(value) and "__class__" in getattr(getattr(value, "__code__", None),
                                                       "co_freevars", ()):
            # Zero-argument super() would need a CyclesRender instance.
            raise RuntimeError(f"cycles.CyclesRender.{name} uses super(): cannot be reused")
        namespace[name] = value
    return namespace


Hooks = dict[str, Callable[..., None]]


def cycles_based_engine(class_name: str, idname: str, label: str, doc: str,
                        hooks: Callable[[dict[str, Any]], Hooks]) -> type:
    """A RenderEngine class that is Cycles (``cycles_namespace``) but for ``update``, ``render``
    and ``render_frame_finish``, which ``hooks(cycles_methods)`` returns, calling Cycles' own
    where they want to."""
    import bpy

    namespace = cycles_namespace()

    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        bpy.types.RenderEngine.__init__(self, *args, **kwargs)
        self.session = None

    namespace.update(hooks(dict(namespace)))
    namespace.update(__init__=__init__, __doc__=doc, bl_idname=idname, bl_label=label)
    return type(class_name, (bpy.types.RenderEngine,), namespace)


def _capture_hooks(cycles_methods: dict[str, Any]) -> Hooks:
    """The capture engine: Cycles with in-memory pass capture, or presenting a given frame."""

    def update(self: Any, data: Any, depsgraph: Any) -> None:
        if session.present is None:
            cycles_methods["update"](self, data, depsgraph)

    def render(self: Any, depsgraph: Any) -> None:
        if session.present is not None:
            scene = depsgraph.scene
            scale = scene.render.resolution_percentage / 100.0
            width = int(scene.render.resolution_x * scale)
            height = int(scene.render.resolution_y * scale)
            write_result(self, width, height, session.present)
            return
        cycles_methods["render"](self, depsgraph)

    def render_frame_finish(self: Any) -> None:
        if session.present is not None:
            return
        # Cycles completes tiled results here, so the result is read afterwards.
        cycles_methods["render_frame_finish"](self)
        if session.sink is not None and not self.test_break():
            session.sink(self.get_result())

    return {"update": update, "render": render, "render_frame_finish": render_frame_finish}


def is_registered() -> bool:
    return _engine_class is not None


def register() -> None:
    global _engine_class
    import bpy

    if _engine_class is None:
        _engine_class = cycles_based_engine(
            "AffinityCyclesEngine", IDNAME, "Cycles (Affinity Denoiser capture)",
            "Cycles with in-memory pass capture (internal to the Affinity Denoiser).", _capture_hooks)
    bpy.utils.register_class(_engine_class)


def unregister() -> None:
    global _engine_class
    import bpy

    if _engine_class is not None:
        bpy.utils.unregister_class(_engine_class)
        _engine_class = None
