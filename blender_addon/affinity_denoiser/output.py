"""Where denoised frames go, and writing them atomically without overwriting anything.

Files of one frame F (four digits, more when needed):

- ``denoised_FFFF.exr``: the denoised linear RGBA, 32-bit float, before compositing;
- ``final_FFFF.<ext>``: the scene's own output format, composited from the denoised frame;
- ``samples/frame_FFFF.exr`` (optional): the per-sample frame file of docs/FRAME_FILES.md.

The default folder is ``affinity_denoised`` beside the render output. When any file a run would
write already exists there, the run uses ``affinity_denoised_001`` (``_002``, ...) instead, so
nothing rendered before is overwritten. Before the first sub-render the folder is made and a
test file written into it (``prepare_folder``), so that an unwritable folder is named before
any rendering. Every file is written under a temporary name in the same folder and renamed into
place when complete: a cancelled or failed write leaves no file.
"""

from __future__ import annotations

import errno
import itertools
import os
import tempfile
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

DEFAULT_FOLDER_NAME = "affinity_denoised"
SAMPLES_SUBFOLDER = "samples"


def frame_tag(frame: int) -> str:
    return f"{frame:04d}" if frame >= 0 else f"-{-frame:04d}"


def denoised_name(frame: int) -> str:
    return f"denoised_{frame_tag(frame)}.exr"


def final_name(frame: int, extension: str) -> str:
    return f"final_{frame_tag(frame)}{extension}"


def sample_frame_name(frame: int) -> str:
    return os.path.join(SAMPLES_SUBFOLDER, f"frame_{frame_tag(frame)}.exr")


def base_folder(scene: Any, folder_setting: str) -> str:
    """The folder the user asked for, or ``affinity_denoised`` beside the render output."""
    import bpy

    if folder_setting:
        return os.path.abspath(bpy.path.abspath(folder_setting))
    # An empty path, or '//' in an unsaved file, means the working directory (as for Blender).
    render_path = bpy.path.abspath(scene.render.filepath)
    render_dir = render_path if render_path.endswith(os.sep) else os.path.dirname(render_path)
    return os.path.join(os.path.abspath(render_dir or "."), DEFAULT_FOLDER_NAME)


def choose_run_folder(base: str, names: Iterable[str]) -> str:
    """``base``, or the first ``base_NNN`` in which none of ``names`` exists yet."""
    names = list(names)
    for index in itertools.count():
        folder = base if index == 0 else f"{base}_{index:03d}"
        if not any(os.path.lexists(os.path.join(folder, n)) for n in names):
            return folder
    raise AssertionError("unreachable")


class FolderNotWritable(RuntimeError):
    """The output folder cannot be made or written into."""


def _reason(error: OSError) -> str:
    if error.errno == errno.EROFS:
        return "read-only file system"
    if error.errno in (errno.EACCES, errno.EPERM):
        return "permission denied (read-only)"
    return error.strerror or str(error)


def prepare_folder(folder: str) -> list[str]:
    """Makes ``folder`` (and its missing parents) and writes and removes a test file in it.

    Returns the folders it made, outermost first, for ``remove_empty_folders``. Raises
    FolderNotWritable naming the folder and the reason, having removed what it made."""
    missing: list[str] = []
    path = os.path.abspath(folder)
    while not os.path.isdir(path):
        if os.path.lexists(path):
            raise FolderNotWritable(
                f"the output folder {folder} is not writable: {path} is a file, not a folder")
        missing.append(path)
        parent = os.path.dirname(path)
        if parent == path:
            break
        path = parent
    created: list[str] = []
    try:
        for path in reversed(missing):
            try:
                os.mkdir(path)
            except OSError as error:
                raise FolderNotWritable(f"the output folder {folder} is not writable: cannot "
                                        f"make {path}: {_reason(error)}") from error
            created.append(path)
        try:
            handle, probe = tempfile.mkstemp(prefix=".affinity-write-test-", dir=folder)
            os.close(handle)
            os.remove(probe)
        except OSError as error:
            raise FolderNotWritable(
                f"the output folder {folder} is not writable: {_reason(error)}") from error
    except FolderNotWritable:
        remove_empty_folders(created)
        raise
    return created


def remove_empty_folders(created: list[str]) -> None:
    """Removes the folders ``prepare_folder`` made, innermost first, where they are empty."""
    for path in reversed(created):
        try:
            os.rmdir(path)
        except OSError:
            return  # not empty (or gone): neither it nor its parents are removed


_temp_counter = itertools.count()


def write_atomic(path: str, write: Callable[[str], None]) -> None:
    """Calls ``write(temporary_path)`` and renames the result to ``path``.

    The temporary file sits in the same folder and keeps the extension (Blender picks writers
    by it). It is removed if ``write`` fails or is interrupted. An existing ``path`` is never
    replaced: that would overwrite a file the user has.
    """
    folder, name = os.path.split(path)
    os.makedirs(folder, exist_ok=True)
    stem, extension = os.path.splitext(name)
    temporary = os.path.join(folder, f".{stem}.tmp-{os.getpid()}-{next(_temp_counter)}{extension}")
    try:
        write(temporary)
        if not os.path.isfile(temporary):
            raise OSError(f"{path}: nothing was written")
        if os.path.lexists(path):
            raise FileExistsError(f"{path}: exists already, not overwritten")
        os.rename(temporary, path)
    finally:
        if os.path.lexists(temporary):
            os.remove(temporary)


def write_float_exr(path: str, rgba: np.ndarray) -> None:
    """Writes (H, W, 4) linear RGBA (top row first) as a 32-bit float OpenEXR, atomically."""
    import bpy

    height, width = rgba.shape[:2]

    def write(temporary: str) -> None:
        image = bpy.data.images.new(
            "affinity_denoised_tmp", width, height, alpha=True, float_buffer=True
        )
        try:
            # Non-Color before the pixels: with a 'Linear' space, saving applied a view transform.
            image.colorspace_settings.name = "Non-Color"
            image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1], np.float32).ravel())
            if hasattr(image, "use_half_precision"):
                image.use_half_precision = False
            image.filepath_raw = temporary
            image.file_format = "OPEN_EXR"
            image.save()
        finally:
            bpy.data.images.remove(image)

    write_atomic(path, write)


def write_render_result(path: str, scene: Any) -> None:
    """Saves the current Render Result (after compositing) in the scene's format, atomically."""
    import bpy

    result = bpy.data.images.get("Render Result")
    if result is None:
        raise RuntimeError("Blender produced no render result to save")
    write_atomic(path, lambda temporary: result.save_render(temporary, scene=scene))
