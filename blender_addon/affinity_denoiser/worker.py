"""The render worker (started by render_job.py): opens the .blend, then renders and denoises
each frame asked for on standard input, carrying the sequence's history from frame to frame.

A frame that does not follow the last one denoised starts a new history. When that frame is
not the first of the animation, the worker first renders and denoises the ``warmup_frames``
frames before it without returning them, so that a chunk of an animation rendered on its own
(a render farm's task) gets frames close to those of one continuous run (docs/BLENDER.md,
"Render farms"). Each frame's Cycles noise depends on the frame and the scene's seed only
(the capture animates it), so a warm-up frame is the same noise as in the continuous run.
"""

from __future__ import annotations

import json
import os
import sys
import traceback
from typing import Any

import numpy as np

from . import engine, pipeline


def frames_to_render(last_frame: int | None, frame: int, frame_start: int, frame_step: int,
                     warmup_frames: int) -> tuple[list[int], bool]:
    """The warm-up frames to render before ``frame``, and whether the history must restart.

    The history continues when ``frame`` follows ``last_frame`` by one step of the animation;
    otherwise it restarts, warmed up by up to ``warmup_frames`` frames of the animation's grid
    (``frame_start``, ``frame_start + frame_step``, ...) before ``frame``, none before
    ``frame_start``."""
    step = max(1, frame_step)
    if last_frame is not None and frame == last_frame + step:
        return [], False
    first = max(frame_start, frame - warmup_frames * step)
    offset = (first - frame_start) % step  # onto the animation's grid
    if offset:
        first += step - offset
    return list(range(first, frame, step)), True


class _Replies:
    def __init__(self, fd: int) -> None:
        self._file = os.fdopen(fd, "w", encoding="utf-8", buffering=1)

    def send(self, message: dict[str, Any]) -> None:
        self._file.write(json.dumps(message) + "\n")
        self._file.flush()


def _render(capture: pipeline.SequenceCapture, frame: int, replies: _Replies,
            done: int, total: int, label: str) -> pipeline.DenoisedFrame:
    spp = capture.settings.samples_per_frame

    def before_sample(sample: int) -> None:
        replies.send({"progress": (done * spp + sample) / (total * spp),
                      "text": f"{label}, sample {sample + 1}/{spp}"})

    return pipeline.run_frame(capture.frame(frame, before_sample))


def _save_passes(folder: str, frame: int, denoised: pipeline.DenoisedFrame,
                 wanted: list[str]) -> dict[str, str]:
    """Writes the passes the engine's result has (Combined: the denoised image) as .npy files,
    each complete before its name is sent; returns pass name -> file name."""
    images = dict(denoised.mean)
    images[pipeline.passes.PASS_NAMES["combined"][0]] = denoised.rgba
    files = {}
    for index, name in enumerate(wanted):
        image = images.get(name)
        if image is None:
            continue
        file_name = f"frame_{frame}_{index}.npy"
        temporary = os.path.join(folder, file_name + ".part")
        with open(temporary, "wb") as handle:
            np.save(handle, np.ascontiguousarray(image, np.float32))
        os.replace(temporary, os.path.join(folder, file_name))
        files[name] = file_name
    return files


def _animation_grid(saved_blend: str, scene_name: str) -> tuple[int, int] | None:
    """The first frame and step of the animation as saved in ``saved_blend``; None when it
    has no such scene."""
    import bpy

    if not saved_blend or not os.path.isfile(saved_blend):
        return None
    bpy.ops.wm.open_mainfile(filepath=saved_blend, load_ui=False)
    scene = bpy.data.scenes.get(scene_name)
    return None if scene is None else (scene.frame_start, scene.frame_step)


def _serve(arguments: dict[str, Any], replies: _Replies) -> None:
    import bpy

    # The animation's grid is the saved file's; when that is the file opened below, read there.
    saved = arguments["saved_blend"]
    grid = _animation_grid(saved, arguments["scene"]) if saved != arguments["blend"] else None
    bpy.ops.wm.open_mainfile(filepath=arguments["blend"], load_ui=False)
    if not engine.is_registered():  # an extension enabled in this Blender registered it
        engine.register()
    scene = bpy.data.scenes.get(arguments["scene"])
    if scene is None:
        raise RuntimeError(f"the scene {arguments['scene']!r} is not in {arguments['blend']}")
    view_layer = scene.view_layers.get(arguments["view_layer"])
    if view_layer is None:
        raise RuntimeError(f"the view layer {arguments['view_layer']!r} is not in scene "
                           f"{scene.name!r}")
    frame_start, frame_step = grid or (scene.frame_start, scene.frame_step)
    settings = pipeline.Settings(**arguments["settings"])
    timings = pipeline.Timings()
    with bpy.context.temp_override(scene=scene, view_layer=view_layer), \
            pipeline.capture_setup(scene, view_layer, settings):
        capture = pipeline.SequenceCapture(scene, view_layer, settings, timings)
        for line in sys.stdin:
            request = json.loads(line)
            frame = int(request["frame"])
            warmup, restart = frames_to_render(capture.last_frame, frame, frame_start,
                                               frame_step, arguments["warmup_frames"])
            if restart:
                capture.reset()
            total = len(warmup) + 1
            for number, warm in enumerate(warmup):
                _render(capture, warm, replies, number, total,
                        f"warm-up frame {warm} ({number + 1}/{len(warmup)})")
            denoised = _render(capture, frame, replies, len(warmup), total, f"frame {frame}")
            files = _save_passes(arguments["folder"], frame, denoised, list(request["passes"]))
            replies.send({"frame": frame, "passes": files, "warmup": warmup})


def main(arguments: dict[str, Any]) -> None:
    replies = _Replies(arguments["reply_fd"])
    status = 0
    try:
        _serve(arguments, replies)
    except Exception as exc:  # the boundary: the engine shows the message
        traceback.print_exc()
        replies.send({"error": str(exc) or type(exc).__name__})
        status = 1
    # Everything is written and sent. bpy 4.5 as a module hangs when Python exits after the
    # add-on's classes were registered (4.2 crashes): end without Python's exit.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
