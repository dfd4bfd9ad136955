"""The operators as a batch user calls them (``blender -b ... --python-expr``), and the panel."""

from __future__ import annotations

import os
from typing import Any

import bpy
import pytest

import scenes
from conftest import CORE_AVAILABLE
from affinity_denoiser import backend


def _scene(tmp_path: Any) -> Any:
    scene = scenes.build_scene(width=32, height=24, frames=2, spp=2)
    scene.render.filepath = str(tmp_path / "out" / "frame_")
    settings = scene.affinity_denoiser
    settings.enabled = True
    settings.samples_per_frame = 2
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

    def column(self, **_: Any) -> "_Layout":
        return self

    def row(self, **_: Any) -> "_Layout":
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
    panel_class.draw_header(fake, context)
    assert fake.layout.drawn[:6] == ["samples_per_frame", "model_path", "fast_arithmetic", "temporal",
                                     "output_folder", "keep_sample_frames"]
    assert "affinity_denoiser.render_frame" in fake.layout.drawn
    assert "affinity_denoiser.render_animation" in fake.layout.drawn
    assert fake.layout.drawn[-1] == "enabled"
    scene.render.engine = "BLENDER_WORKBENCH"
    assert not panel_class.poll(context)
