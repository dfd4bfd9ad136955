"""The worker process behind the "Cycles + Affinity" render engine.

A frame of the denoiser is S one-sample Cycles renders, and Cycles cannot render several times
inside one call of an engine's ``render()`` (a second ``cycles.engine.reset`` there crashed
Blender: docs/BLENDER.md, "The render engine"). So the engine hands each frame to a worker: a
background Blender (or, where Blender is the ``bpy`` module, a Python) process that opens the
same .blend, renders the frame's sub-renders through the capture engine and denoises them with
the core, keeping the sequence's history from frame to frame (worker.py). The engine gets the
denoised passes back and fills Blender's render result with them, so Blender's own pipeline
(compositor, file output, frame numbering, placeholders, overwrite) does the rest.

One worker serves one view layer of one render job (F12, or a whole ``-a`` animation); it is
stopped when the job completes or is cancelled. Requests go to its standard input, one JSON
line each; replies come back on a pipe of their own, one JSON line each, so that Blender's
console output cannot be mistaken for them. Pass images travel as .npy files in a private
temporary folder, removed with the worker.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from . import pipeline


class WorkerFailed(RuntimeError):
    """The worker process reported an error or ended without a reply."""


@dataclass
class JobSettings:
    """What the worker needs besides the .blend: the scene's denoiser settings, and how many
    frames before a chunk's first it renders to warm the history up. The animation's first
    frame and step are those of the saved .blend: a farm's ``-s``/``-e`` (or a script) set the
    chunk in memory, not where the animation starts."""

    settings: pipeline.Settings
    warmup_frames: int
    #: The saved .blend whose scene gives the animation's first frame and step (empty: the
    #: .blend the worker opens).
    saved_blend: str = ""


def _command(arguments: dict[str, Any]) -> list[str]:
    """How to start a worker on this Blender: the same executable, without a window."""
    import bpy

    payload = json.dumps(arguments)
    if bpy.app.binary_path:  # Blender itself: a background Blender of the same installation
        return [bpy.app.binary_path, "--background", "--python-exit-code", "1",
                "--python-expr", _BOOTSTRAP, "--", payload]
    return [sys.executable, "-c", _BOOTSTRAP, payload]  # Blender as a Python module (PyPI's bpy)


#: The worker's first lines: the parent's import path, then this package, by name where that
#: imports (an enabled extension: its classes are registered already), else from its folder.
_BOOTSTRAP = """\
import importlib, importlib.util, json, sys
arguments = json.loads(sys.argv[-1])
sys.path.extend(p for p in arguments["sys_path"] if p not in sys.path)
name = arguments["package"]
try:
    importlib.import_module(name)
except ImportError:
    spec = importlib.util.spec_from_file_location(
        name, arguments["package_dir"] + "/__init__.py",
        submodule_search_locations=[arguments["package_dir"]])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
importlib.import_module(name + ".worker").main(arguments)
"""


class RenderJob:
    """One worker process, rendering and denoising frames of one view layer on request."""

    def __init__(self, blend: str, scene: str, view_layer: str, job: JobSettings) -> None:
        self.folder = tempfile.mkdtemp(prefix="affinity-render-")
        self._log_path = os.path.join(self.folder, "worker.log")
        package = __package__ or "affinity_denoiser"
        arguments = {
            "package": package,
            "package_dir": os.path.dirname(os.path.abspath(__file__)),
            "sys_path": [p for p in sys.path if p],
            "blend": blend,
            "scene": scene,
            "view_layer": view_layer,
            "settings": asdict(job.settings),
            "warmup_frames": job.warmup_frames,
            "saved_blend": job.saved_blend,
            "folder": self.folder,
        }
        read_end, write_end = os.pipe()
        arguments["reply_fd"] = write_end
        self._replies = os.fdopen(read_end, "rb", buffering=0)
        self._buffer = b""
        try:
            with open(self._log_path, "wb") as log:
                self._process = subprocess.Popen(
                    _command(arguments), stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                    stderr=log, pass_fds=(write_end,), start_new_session=True)
        except OSError as error:  # no such program, no memory: nothing may be left behind
            self.close()
            raise WorkerFailed(f"cannot start the render worker: {error}") from error
        finally:
            os.close(write_end)

    def _log_tail(self, lines: int = 25) -> str:
        try:
            with open(self._log_path, encoding="utf-8", errors="replace") as log:
                return "".join(log.readlines()[-lines:]).strip()
        except OSError:
            return ""

    def _next_reply(self, cancelled: Callable[[], bool]) -> dict[str, Any] | None:
        """The worker's next reply; None when ``cancelled()`` turned true while waiting."""
        while b"\n" not in self._buffer:
            if cancelled():
                return None
            ready, _, _ = select.select([self._replies], [], [], 0.1)
            if not ready:
                continue
            chunk = self._replies.read(65536)
            if not chunk:  # the worker closed its end: it has ended
                code = self._process.wait()
                tail = self._log_tail()
                raise WorkerFailed(f"the render worker ended (exit code {code}) without "
                                   f"finishing the frame" + (f"; its last output:\n{tail}" if tail else ""))
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        return json.loads(line)

    def render(self, frame: int, pass_names: list[str],
               progress: Callable[[float, str], None],
               cancelled: Callable[[], bool]) -> dict[str, np.ndarray] | None:
        """Renders and denoises ``frame``; returns its passes by name (Combined: the denoised
        image), or None when ``cancelled()`` turned true (the worker is then stopped)."""
        request = {"frame": frame, "passes": pass_names}
        try:
            assert self._process.stdin is not None
            self._process.stdin.write((json.dumps(request) + "\n").encode())
            self._process.stdin.flush()
        except (BrokenPipeError, OSError):
            pass  # the worker has ended: _next_reply says how
        while True:
            reply = self._next_reply(cancelled)
            if reply is None:
                self.close(kill=True)
                return None
            if "error" in reply:
                raise WorkerFailed(reply["error"])
            if "progress" in reply:
                progress(float(reply["progress"]), str(reply.get("text", "")))
                continue
            passes = {}
            for name, file_name in reply["passes"].items():
                path = os.path.join(self.folder, file_name)
                passes[name] = np.load(path)
                os.unlink(path)
            return passes

    def close(self, kill: bool = False) -> None:
        """Stops the worker (``kill``: at once, as on Esc; it holds nothing that must be
        saved) and removes the temporary folder."""
        process = getattr(self, "_process", None)
        if process is not None and process.poll() is None:
            try:
                if kill:
                    process.kill()
                elif process.stdin is not None:
                    process.stdin.close()  # the worker's loop ends on end of input
                process.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                process.kill()
                process.wait()
        if process is not None and process.stdin is not None and not process.stdin.closed:
            try:
                process.stdin.close()
            except OSError:  # a broken pipe to a worker that is gone
                pass
        if getattr(self, "_replies", None) is not None:
            self._replies.close()
            self._replies = None
        shutil.rmtree(self.folder, ignore_errors=True)
