"""Several processes rendering one animation into one folder write each frame once.

Blender's convention for that is Placeholders + no Overwrite: before a frame it skips the frame
if its file exists, else creates an empty file and renders. The check and the creation are two
steps, so two processes that reach a frame at the same moment both render and both write it
(measured: two processes started together both rendered frame 1). With our engine each frame
is expensive, so the frame is also claimed atomically, by creating a hidden claim file beside it
with O_EXCL, between Blender's check and the render (the ``render_pre`` handler). A process
that loses the claim renders nothing for that frame, and its write of that frame goes to a
private folder (Blender writes to the scene's output path of the moment) that is then deleted.
A claim is removed once its frame is written or the render stops.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from typing import Any

from . import engine

#: The claims this process holds: claim path.
_held: list[str] = []
#: While a lost frame is rendered: (the user's output path to put back, the private folder).
_diverted: tuple[str, str] | None = None


def claim_path(frame_path: str) -> str:
    folder, name = os.path.split(frame_path)
    return os.path.join(folder, f".{name}.affinity-claim")


def _applies(scene: Any) -> bool:
    render = scene.render
    return (render.engine == engine.DENOISING_ENGINE and render.use_placeholder
            and not render.use_overwrite and not render.is_movie_format)


def frame_lost() -> bool:
    """Whether another process renders the current frame (this one writes it nowhere)."""
    return _diverted is not None


def before_frame(scene: Any, *_: Any) -> None:
    """``render_pre``: claims the frame, or diverts this process's write of it."""
    global _diverted
    if not _applies(scene):
        return
    import bpy

    frame_path = bpy.path.abspath(scene.render.frame_path(frame=scene.frame_current))
    claim = claim_path(frame_path)
    try:
        os.close(os.open(claim, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
    except FileExistsError:
        folder = tempfile.mkdtemp(prefix="affinity-lost-frame-")
        _diverted = (scene.render.filepath, folder)
        scene.render.filepath = os.path.join(folder, "frame_")
        return
    _held.append(claim)


def after_frame(scene: Any, *_: Any) -> None:
    """``render_post`` (after the frame is written), ``render_cancel``, ``render_complete``:
    releases the claims and puts a diverted output path back."""
    global _diverted
    while _held:
        try:
            os.unlink(_held.pop())
        except FileNotFoundError:
            pass
    if _diverted is not None:
        filepath, folder = _diverted
        _diverted = None
        scene.render.filepath = filepath
        shutil.rmtree(folder, ignore_errors=True)


HANDLERS = (("render_pre", before_frame), ("render_post", after_frame),
            ("render_cancel", after_frame), ("render_complete", after_frame))
