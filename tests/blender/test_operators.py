"""The operators as a batch user calls them (``blender -b ... --python-expr``), and the panel."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any

import bpy
import pytest
import scenes
from conftest import CORE_AVAILABLE, CORE_PATH, ROOT

from affinity_denoiser import backend, operators


def _scene(tmp_path: Any) -> Any:
    scene = scenes.build_scene(width=32, height=24, frames=2, spp=2)
    scene.render.filepath = str(tmp_path / "out" / "frame_")
    scene.affinity_denoiser.samples_per_frame = 2
    return scene


def test_render_animation_operator(tmp_path: Any, capfd: pytest.CaptureFixture[str]) -> None:
    _scene(tmp_path)
    assert bpy.ops.affinity_denoiser.render_animation() == {"FINISHED"}
    assert sorted(os.listdir(tmp_path / "out" / "affinity_denoised")) == [
        "denoised_0001.exr", "denoised_0002.exr", "final_0001.png", "final_0002.png"]
    console = capfd.readouterr().out
    assert "affinity_denoiser: frame 2 (2/2), sample 2/2 [3/4 sub-renders]" in console
    assert "affinity_denoiser: denoised 2 frame(s) into" in console


def test_render_frame_operator_without_temporal_history(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    scene.affinity_denoiser.temporal = False
    scene.frame_set(2)
    assert bpy.ops.affinity_denoiser.render_frame() == {"FINISHED"}
    assert sorted(os.listdir(tmp_path / "out" / "affinity_denoised")) == [
        "denoised_0002.exr", "final_0002.png"]


class _ResetCounter(backend.MeanDenoiser):
    resets = 0

    def reset(self) -> None:
        type(self).resets += 1


@pytest.mark.parametrize("temporal, resets", [(True, 0), (False, 2)])
def test_temporal_switch_resets_history_per_frame(tmp_path: Any, temporal: bool,
                                                  resets: int) -> None:
    scene = _scene(tmp_path)
    scene.affinity_denoiser.temporal = temporal
    previous = backend._factory
    _ResetCounter.resets = 0
    backend.set_denoiser_factory(_ResetCounter)
    try:
        assert bpy.ops.affinity_denoiser.render_animation() == {"FINISHED"}
    finally:
        backend.set_denoiser_factory(previous)
    assert _ResetCounter.resets == resets


def test_errors_are_reported_with_the_core_message(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    scene.affinity_denoiser.model_path = str(tmp_path / "missing_model.affw")
    previous = backend._factory
    backend.set_denoiser_factory(None)  # the real core, or its absence
    try:
        with pytest.raises(RuntimeError) as failure:
            bpy.ops.affinity_denoiser.render_frame()
    finally:
        backend.set_denoiser_factory(previous)
    message = str(failure.value)
    assert "missing_model.affw" in message if CORE_AVAILABLE else "affinity core" in message
    assert not os.path.exists(tmp_path / "out")


def test_operators_need_cycles(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    scene.render.engine = "BLENDER_WORKBENCH"
    assert not bpy.ops.affinity_denoiser.render_frame.poll()
    scene.render.engine = "CYCLES"
    assert bpy.ops.affinity_denoiser.render_frame.poll()


def test_panel_and_settings_are_registered() -> None:
    assert hasattr(bpy.types, "AFFINITY_DENOISER_PT_render")
    settings = scenes.build_scene(frames=1).affinity_denoiser
    assert (settings.samples_per_frame, settings.temporal, settings.model_path,
            settings.output_folder) == (4, True, "", "")
    settings.samples_per_frame = 99
    assert settings.samples_per_frame == 8


class _Layout:
    """Records what a panel draws (there is no window in background mode)."""

    def __init__(self) -> None:
        self.drawn: list[str] = []
        self.use_property_split = self.use_property_decorate = False
        self.active = self.enabled = True

    def column(self, **_: Any) -> _Layout:
        return self

    def row(self, **_: Any) -> _Layout:
        return self

    def prop(self, data: Any, name: str, **_: Any) -> None:
        assert hasattr(data, name), name
        self.drawn.append(name)

    def operator(self, idname: str, **_: Any) -> None:
        module, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, module), name), idname
        self.drawn.append(idname)

    def label(self, text: str = "", **_: Any) -> None:
        self.drawn.append(text)


def test_panel_draws_every_setting_and_both_operators() -> None:
    scene = scenes.build_scene(frames=1)
    panel_class = bpy.types.AFFINITY_DENOISER_PT_render
    context = type("Context", (), {"scene": scene})()
    assert panel_class.poll(context)
    fake = type("Panel", (), {"layout": _Layout()})()
    panel_class.draw(fake, context)
    assert fake.layout.drawn[:9] == ["samples_per_frame", "model_path", "precision", "temporal",
                                     "warmup_frames", "preroll_frames", "preroll_samples", "output_folder",
                                     "keep_sample_frames"]
    assert "affinity_denoiser.render_frame" in fake.layout.drawn
    assert "affinity_denoiser.render_animation" in fake.layout.drawn
    scene.render.engine = "AFFINITY_DENOISER"
    assert panel_class.poll(context)
    scene.render.engine = "BLENDER_WORKBENCH"
    assert not panel_class.poll(context)


def _choose_eevee(scene: Any) -> None:
    for identifier in ("BLENDER_EEVEE", "BLENDER_EEVEE_NEXT"):  # 5.0, 4.2
        try:
            scene.render.engine = identifier
            return
        except TypeError:
            continue
    raise AssertionError("no EEVEE engine in this Blender")


class _Runner(operators._DenoiseRenderBase):
    """The operators' code run directly, without their poll (as a script could)."""

    def __init__(self) -> None:
        self.reports: list[tuple[set[str], str]] = []

    def report(self, kind: set[str], message: str) -> None:
        self.reports.append((kind, message))

    def frames(self, scene: Any) -> list[int]:
        return [scene.frame_current]


@pytest.mark.parametrize("operator", ["render_frame", "render_animation"])
def test_with_eevee_the_operators_say_that_they_need_cycles(tmp_path: Any, operator: str) -> None:
    """Issue 40, item 5: the poll failed with Blender's "poll() failed, context is incorrect"."""
    scene = _scene(tmp_path)
    _choose_eevee(scene)
    call = getattr(bpy.ops.affinity_denoiser, operator)
    assert not call.poll()
    with pytest.raises(RuntimeError) as failure:
        call()
    message = str(failure.value)
    assert "context is incorrect" not in message
    assert "needs Cycles" in message and "EEVEE" in message, message
    # Run anyway: a clear error before anything is rendered or written.
    runner = _Runner()
    assert runner.execute(bpy.context) == {"CANCELLED"}
    assert len(runner.reports) == 1 and runner.reports[0][0] == {"ERROR"}
    assert "needs Cycles" in runner.reports[0][1] and "EEVEE" in runner.reports[0][1]
    assert not os.path.exists(tmp_path / "out")


def test_an_unwritable_output_folder_stops_the_operator_before_rendering(
        tmp_path: Any, capfd: pytest.CaptureFixture[str]) -> None:
    """Issue 40, item 5: "Could not write image: Invalid argument" came after the render."""
    scene = _scene(tmp_path)
    (tmp_path / "a_file").write_bytes(b"not a folder")
    folder = str(tmp_path / "a_file" / "denoised")
    scene.affinity_denoiser.output_folder = folder
    with pytest.raises(RuntimeError) as failure:
        bpy.ops.affinity_denoiser.render_animation()
    message = str(failure.value)
    assert f"the output folder {folder} is not writable" in message, message
    assert "sub-renders]" not in capfd.readouterr().out  # no sub-render started
    assert (tmp_path / "a_file").read_bytes() == b"not a folder"
    assert scene.affinity_denoiser.last_output_folder == ""


def test_a_script_learns_where_the_frames_went(tmp_path: Any,
                                               capfd: pytest.CaptureFixture[str]) -> None:
    """Issue 40, item 5: the operator returned {'FINISHED'} only, and switched to
    affinity_denoised_001 silently when the first folder had the frames already."""
    scene = _scene(tmp_path)
    settings = scene.affinity_denoiser
    assert settings.last_output_folder == ""
    with pytest.raises(AttributeError):
        settings.last_output_folder = str(tmp_path / "elsewhere")  # read-only
    assert bpy.ops.affinity_denoiser.render_frame() == {"FINISHED"}
    first = str(tmp_path / "out" / "affinity_denoised")
    assert settings.last_output_folder == first
    assert f"Info: denoised 1 frame(s) into {first}\n" in capfd.readouterr().out
    # The same frame again: its files exist, so the run goes to a new folder, and says so.
    assert bpy.ops.affinity_denoiser.render_frame() == {"FINISHED"}
    second = first + "_001"
    assert settings.last_output_folder == second
    assert sorted(os.listdir(second)) == ["denoised_0001.exr", "final_0001.png"]
    console = capfd.readouterr().out
    assert (f"Info: denoised 1 frame(s) into {second} ({first} has files of these frames "
            "already; nothing was overwritten)") in console, console


def test_no_switch_that_does_nothing(tmp_path: Any) -> None:
    """Issue 40, item 5: the panel's header switch ("enabled", described as "Denoise renders
    with the Affinity Denoiser") only greyed out the panel's buttons: F12 ignored it and the
    operators ran without it. The buttons are what starts a denoise-render; the switch is gone."""
    scene = scenes.build_scene(width=32, height=24, frames=1, spp=2)
    scene.render.filepath = str(tmp_path / "out" / "frame_")
    settings = scene.affinity_denoiser
    assert "enabled" not in settings.bl_rna.properties
    panel_class = bpy.types.AFFINITY_DENOISER_PT_render
    assert "draw_header" not in vars(panel_class)
    fake = type("Panel", (), {"layout": _Layout()})()
    panel_class.draw(fake, type("Context", (), {"scene": scene})())
    assert fake.layout.enabled == (not backend.core_status())  # the buttons, with a working core
    assert "enabled" not in fake.layout.drawn
    settings.samples_per_frame = 2
    assert bpy.ops.affinity_denoiser.render_frame() == {"FINISHED"}
    assert settings.last_output_folder == str(tmp_path / "out" / "affinity_denoised")


# A fresh bpy: plain Cycles renders before and after the add-on is registered, and after a
# denoise-render, and the console of it all.
_CONSOLE = """
import json, os, sys
import numpy as np
import bpy
import scenes
import affinity_denoiser

out = sys.argv[1]
scene = scenes.build_scene(width=32, height=24, frames=1, spp=2)


def plain(name):
    scene.render.filepath = os.path.join(out, name + ".png")
    bpy.ops.render.render(write_still=True)
    return scenes.read_image(scene.render.filepath)


before = plain("before")
affinity_denoiser.register()
registered = plain("registered")
scene.render.filepath = os.path.join(out, "frame_")
scene.affinity_denoiser.samples_per_frame = 2
assert bpy.ops.affinity_denoiser.render_frame() == {"FINISHED"}
after_denoise = plain("after_denoise")
affinity_denoiser.unregister()
unregistered = plain("unregistered")
print("RESULT " + json.dumps({
    "mean": float(before[..., :3].mean()),
    "same": [bool(np.array_equal(before, image))
             for image in (registered, after_denoise, unregistered)],
}))
"""


def test_no_console_noise_and_plain_cycles_renders_are_unchanged(tmp_path: Any) -> None:
    """Issue 40, item 5: every run printed ~22 lines of "WARNING unable to get Python class
    for RNA struct 'CYCLES'". The cause: registering a subclass of Cycles' own engine class
    took Cycles' Python class off its RNA type, so every call into the Cycles engine failed
    while the add-on was registered (and after): plain Cycles renders came out black."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([CORE_PATH,
                                         os.path.join(ROOT, "blender_addon"),
                                         os.path.dirname(os.path.abspath(__file__))])
    result = subprocess.run([sys.executable, "-c", _CONSOLE, str(tmp_path)], env=env,
                            cwd=str(tmp_path), capture_output=True, text=True, timeout=300)
    console = result.stdout + result.stderr
    lines = [line for line in result.stdout.splitlines() if line.startswith("RESULT ")]
    assert result.returncode == 0 and lines, console[-3000:]
    assert "unable to get Python class" not in console, console[-3000:]
    assert "bpy.rna" not in console, console[-3000:]
    report = json.loads(lines[-1].removeprefix("RESULT "))
    assert report["mean"] > 0.1
    assert report["same"] == [True, True, True]
