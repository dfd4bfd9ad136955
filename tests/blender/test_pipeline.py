"""A denoise-render of 3 frames x 4 samples at 64x48 (glossy, glass, emitters, moving camera),
checked against plain Cycles renders, the feature schema and the user's data."""

from __future__ import annotations

import math
import os
from typing import Any

import bpy
import numpy as np
import pytest
import scenes
from conftest import CORE_IO_AVAILABLE, capture, material_snapshot

from affinity_denoiser import backend, compositor, features, passes, pipeline

REFERENCE_SPP = 256


def _scene_settings(scene: Any) -> dict[str, Any]:
    layer = scene.view_layers[0]
    names = ("use_pass_z", "use_pass_diffuse_direct", "use_pass_diffuse_indirect",
             "use_pass_diffuse_color", "use_pass_emit", "use_pass_combined")
    return {
        "engine": scene.render.engine,
        "persistent": scene.render.use_persistent_data,
        "single_layer": scene.render.use_single_layer,
        "compositing": scene.render.use_compositing,
        "samples": scene.cycles.samples,
        "subset": getattr(scene.cycles, "use_sample_subset", None),
        "offset": scene.cycles.sample_offset,
        "adaptive": scene.cycles.use_adaptive_sampling,
        "denoising": scene.cycles.use_denoising,
        "animated_seed": scene.cycles.use_animated_seed,
        "frame": scene.frame_current,
        "passes": tuple(getattr(layer, n) for n in names),
        "denoising_passes": layer.cycles.denoising_store_passes,
        "aovs": tuple((a.name, a.type) for a in layer.aovs),
        "images": sorted(i.name for i in bpy.data.images),
    }


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The denoise-render, plus plain renders of the same frames to compare with."""
    root = tmp_path_factory.mktemp("pipeline")
    scene = scenes.build_scene()
    scenes.add_exposure_compositor(scene, 1.0)
    scenes.use_float_exr_output(scene)
    scene.render.filepath = str(root / "render" / "frame_")
    scene.frame_set(2)
    before = {"materials": material_snapshot(), "settings": _scene_settings(scene)}

    # No pre-roll: the tests below rebuild the core's input from the kept frames alone.
    job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1, 2, 3], pipeline.Settings(preroll_frames=0))
    job.keep_frames = True
    job.run()
    after = {"materials": material_snapshot(), "settings": _scene_settings(scene)}
    node = compositor.compositing_tree(scene).nodes[compositor.NODE_NAME]
    after["node"] = {"image": bpy.path.abspath(node.image.filepath), "source": node.image.source,
                     "frame_start": node.frame_start, "frame_offset": node.frame_offset,
                     "frame_duration": node.frame_duration}

    assert not scene.cycles.use_animated_seed  # the user's setting, which the capture overrides
    plain, plain_static, reference = {}, {}, {}
    for frame in job.frames:
        scene.frame_set(frame)
        plain_static[frame] = capture(scene)["Combined"][..., :3]
        plain[frame] = capture(scene, lambda s: setattr(s.cycles, "use_animated_seed", True))["Combined"][..., :3]
        scene.cycles.use_animated_seed = False

        def high_spp(s: Any) -> None:
            s.cycles.samples = REFERENCE_SPP
            s.cycles.seed = 1  # independent of the 4 samples being judged

        reference[frame] = capture(scene, high_spp)["Combined"][..., :3]
        scene.cycles.samples, scene.cycles.seed = scenes.SPP, 0
    return {"job": job, "before": before, "after": after, "plain": plain, "plain_static": plain_static,
            "reference": reference, "root": root}


def test_sample_mean_equals_a_full_render(run: dict[str, Any]) -> None:
    if not pipeline.uses_sample_subsets(bpy.context.scene.cycles):
        pytest.skip("one-sample renders reproduce an S-spp render exactly only with sample "
                    "subsets (bpy >= 4.5 checked; 4.2 and 4.3 differ: docs/BLENDER.md)")
    for result in run["job"].results:
        full = run["plain"][result.frame]
        # Sum of per-sample diffuse + specular over the samples = Cycles' 4-spp Combined, with
        # the animated seed the capture turns on (the scene has it off): not the scene's noise.
        np.testing.assert_allclose(result.noisy, full, rtol=1e-5, atol=1e-5)
        assert np.abs(result.noisy - run["plain_static"][result.frame]).mean() > 1e-3


def test_features_within_schema_ranges(run: dict[str, Any]) -> None:
    for result in run["job"].results:
        samples = result.frame_data["samples"]
        assert samples.shape == (scenes.HEIGHT, scenes.WIDTH, scenes.SPP, 18)
        assert np.isfinite(samples).all()
        f = features
        assert (samples[..., f.DIFFUSE:f.SPECULAR + 3] >= 0).all()
        normal = samples[..., f.NORMAL:f.NORMAL + 3]
        length = np.linalg.norm(normal, axis=-1)
        assert np.all((np.abs(length - 1) < 1e-4) | (length == 0))
        depth = samples[..., f.DEPTH]
        assert (depth >= 0).all()
        albedo = samples[..., f.ALBEDO:f.ALBEDO + 3]
        assert ((albedo >= 0) & (albedo <= 1)).all()
        roughness = samples[..., f.ROUGHNESS]
        assert np.all((roughness == 0) | ((roughness >= 0.02) & (roughness <= 1)))
        for channel in (f.EMISSIVE, f.METALLIC, f.TRANSMISSIVE, f.SPECULAR_BOUNCE):
            flag = samples[..., channel]
            assert np.isin(flag, (0.0, 1.0)).all()
            assert flag.any(), f"flag channel {channel} is never set in this scene"
        miss = (length == 0) & (depth == 0)
        assert miss.any() and (samples[..., f.EMISSIVE][miss] == 1).all()
        assert (roughness[miss] == 0).all() and (albedo[miss] == 0).all()


def test_depth_is_the_path_length_from_the_eye() -> None:
    """Where the first hit is not specular, the depth from Cycles' denoising depth (measured
    from the near plane) plus the near plane's distance equals the shader's view distance."""
    from affinity_denoiser import materials, motion, passes

    scene = scenes.build_scene(frames=1)
    layer = scene.view_layers[0]

    def one_sample_with_feature_passes(s: Any) -> None:
        s.cycles.samples = 1
        layer.use_pass_z = layer.use_pass_emit = True
        layer.use_pass_diffuse_direct = layer.use_pass_diffuse_indirect = True
        layer.use_pass_diffuse_color = layer.cycles.denoising_store_passes = True

    with passes.shader_aovs(layer), materials.surface_aovs(bpy.data):
        captured = capture(scene, one_sample_with_feature_passes)
    camera = motion.scene_camera(scene, bpy.context.evaluated_depsgraph_get())
    by_role = passes.by_role(captured, passes.resolve(captured))
    sample = features.sample_features(by_role, camera, motion.ray_start_distance(camera))
    depth, view_distance = sample[..., features.DEPTH], by_role["aov_distance"][..., 0]
    direct = (sample[..., features.SPECULAR_BOUNCE] == 0) & (depth > 0)
    assert direct.mean() > 0.5
    np.testing.assert_allclose(depth[direct], view_distance[direct], rtol=1e-4)
    # Through the mirror and the glass the path is longer than the distance to the first hit.
    bounced = sample[..., features.SPECULAR_BOUNCE] == 1
    assert (depth[bounced & (depth > 0)] > view_distance[bounced & (depth > 0)]).all()


def test_camera_motion_matches_the_vector_pass(run: dict[str, Any]) -> None:
    from affinity_denoiser import motion

    scene = scenes.build_scene()
    layer = scene.view_layers[0]

    def vector_pass(s: Any) -> None:
        s.cycles.samples = 1
        layer.use_pass_vector = True
        layer.use_pass_z = True

    cameras, depth, vectors = {}, {}, {}
    for frame in (1, 2, 3):
        scene.frame_set(frame)
        cameras[frame] = motion.scene_camera(scene, bpy.context.evaluated_depsgraph_get())
        passes = capture(scene, vector_pass)
        depth[frame], vectors[frame] = passes["Depth"][..., 0], passes["Vector"]
    for frame in (2, 3):
        ours, valid = motion.camera_motion(cameras[frame], depth[frame],
                                           cameras[frame - 1], depth[frame - 1])
        # Blender's Vector pass: (x, y) motion into the previous frame, y up.
        theirs = np.stack([vectors[frame][..., 0], -vectors[frame][..., 1]], axis=-1)
        hit = depth[frame] < motion.MISS_DEPTH
        assert np.abs(ours - theirs)[hit].max() < 1e-3
        assert np.linalg.norm(theirs, axis=-1)[hit].mean() > 0.5  # the camera really moves
        assert 0.8 < valid.mean() < 1.0  # some of the image comes into view
    # The pipeline wrote the same vectors for its frames.
    pipeline_motion = run["job"].results[1].frame_data["motion"]
    ours, _ = motion.camera_motion(cameras[2], depth[2], cameras[1], depth[1])
    np.testing.assert_allclose(pipeline_motion, ours, atol=1e-4)
    assert not run["job"].results[0].frame_data["valid"].any()


def test_denoised_output_is_finite_and_written(run: dict[str, Any]) -> None:
    for result in run["job"].results:
        assert np.isfinite(result.denoised).all()
        written = scenes.read_image(result.denoised_path)
        np.testing.assert_array_equal(written[..., :3], result.denoised)
        assert os.path.dirname(result.denoised_path).endswith("affinity_denoised")


def test_compositor_output_is_computed_from_the_denoised_frame(run: dict[str, Any]) -> None:
    for result in run["job"].results:
        denoised = scenes.read_image(result.denoised_path)
        final = scenes.read_image(result.final_path)
        # The user's graph multiplies by 2^1 (Exposure node).
        np.testing.assert_allclose(final[..., :3], 2.0 * denoised[..., :3], rtol=1e-6)


def test_compositor_gets_an_image_node_with_the_denoised_sequence(run: dict[str, Any]) -> None:
    node = run["after"]["node"]
    first = run["job"].results[0]
    assert node["image"] == first.denoised_path and node["source"] == "SEQUENCE"
    assert (node["frame_start"], node["frame_offset"], node["frame_duration"]) == (1, 0, 3)


def test_materials_and_settings_are_restored(run: dict[str, Any]) -> None:
    assert run["after"]["materials"] == run["before"]["materials"]
    before, after = dict(run["before"]["settings"]), dict(run["after"]["settings"])
    # New images: the render result, and the denoised sequence of the compositor's node.
    first = os.path.basename(run["job"].results[0].denoised_path)
    assert set(after.pop("images")) - set(before.pop("images")) == {"Render Result", first}
    assert after == before


def _relative_mse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.mean((image - reference) ** 2 / (reference ** 2 + 1e-2)))


def test_denoised_is_closer_to_the_reference_than_the_noisy_mean(run: dict[str, Any]) -> None:
    errors = []
    for result in run["job"].results:
        reference = run["reference"][result.frame]
        errors.append((_relative_mse(result.noisy, reference),
                       _relative_mse(result.denoised, reference)))
        print(f"frame {result.frame}: relMSE against {REFERENCE_SPP} spp: noisy mean "
              f"{errors[-1][0]:.4f}, denoised {errors[-1][1]:.4f}")
    for noisy, denoised in errors:
        assert denoised < 0.5 * noisy


def test_sample_frames_round_trip_through_the_core(run: dict[str, Any], tmp_path: Any) -> None:
    if not CORE_IO_AVAILABLE:
        pytest.skip("the affinity core is not importable")
    import affinity_core

    frame = run["job"].results[1].frame_data
    path = tmp_path / "frame_0002.exr"
    affinity_core.write_frame(path, frame)
    back = affinity_core.read_frame(path)
    np.testing.assert_array_equal(back["samples"], frame["samples"])
    np.testing.assert_array_equal(back["motion"], frame["motion"])
    assert back["info"]["frame_index"] == 2


def test_streamed_samples_give_what_the_core_gives_on_the_kept_frames(run: dict[str, Any],
                                                                     tmp_path: Any) -> None:
    """Without keep_frames the job streams every sub-render's features to the core
    (add_samples / finish_frame) instead of holding the frame: same renders, same result as
    streaming the kept frames ourselves, and the noisy mean of the whole-frame path."""
    from conftest import CORE_AVAILABLE
    if not CORE_AVAILABLE:
        pytest.skip("the affinity core is not importable")
    import affinity_core

    scene = bpy.context.scene
    scene.render.filepath = str(tmp_path / "render" / "frame_")
    job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1, 2, 3], pipeline.Settings(preroll_frames=0))
    job.run()
    by_hand = affinity_core.Denoiser(backend.CYCLES_MODEL)  # what the panel's empty Model means
    for kept, streamed in zip(run["job"].results, job.results, strict=True):
        assert streamed.frame_data is None
        samples = kept.frame_data["samples"]
        for s in range(samples.shape[2]):
            by_hand.add_samples(samples[:, :, s])
        expected = by_hand.finish_frame({k: v for k, v in kept.frame_data.items() if k != "samples"})
        np.testing.assert_array_equal(streamed.denoised, expected)
        np.testing.assert_allclose(streamed.noisy, kept.noisy, rtol=1e-5, atol=1e-7)
        # Only the depth normalisation separates it from denoising the whole frame: little on
        # average, most beside the emitter (one pixel's difference varies with the Blender
        # version; with the Cycles model on bpy 4.2.23, 3.42 of the frame's maximum 92.9).
        difference = np.abs(streamed.denoised - kept.denoised)
        assert difference.mean() <= 0.01 * np.abs(kept.denoised).mean()
        assert difference.max() <= 0.05 * np.abs(kept.denoised).max()


def test_precision_auto_uses_bfloat16_only_where_the_cpu_has_it(run: dict[str, Any], tmp_path: Any) -> None:
    """The panel's Precision: auto (the default) takes bfloat16 products on CPUs with AVX512-BF16
    and FP32 elsewhere, so a .blend saved with it renders anywhere; fp32 overrides it (the same
    frames within a few thousandths)."""
    from conftest import CORE_AVAILABLE
    if not CORE_AVAILABLE:
        pytest.skip("the affinity core is not importable")
    import affinity_core
    from affinity_denoiser import backend

    expected = "bf16" if affinity_core.bfloat16_supported() else "fp32"
    assert backend.create_denoiser("").model.precision == expected
    assert backend.create_denoiser("", "auto").model.precision == expected
    assert backend.create_denoiser("", "fp32").model.precision == "fp32"
    assert pipeline.Settings.from_properties(bpy.context.scene.affinity_denoiser).precision == "auto"

    scene = bpy.context.scene
    scene.render.filepath = str(tmp_path / "render" / "frame_")
    job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1, 2, 3],
                                 pipeline.Settings(precision="fp32", preroll_frames=0))
    job.keep_frames = True  # as the fixture's job: whole frames, the same depth normalisation
    job.run()
    for automatic, fp32 in zip(run["job"].results, job.results, strict=True):
        a, b = automatic.denoised, fp32.denoised
        assert np.isfinite(b).all()
        assert np.mean(np.abs(a - b) / (np.abs(a) + np.abs(b) + 1e-2)) < 3e-3


def test_passes_cycles_writes_for_the_first_sample_only_are_that_samples() -> None:
    # What the compositor gets besides Combined: Depth is written at sample offset 0 only (the
    # other sub-renders hold 1e10, the no-hit value), so a mean would be half 1e10.
    scene = scenes.build_scene(width=32, height=24, frames=1, spp=2)
    layer = scene.view_layers[0]
    layer.use_pass_z = True
    settings = pipeline.Settings(samples_per_frame=2)
    with pipeline.capture_setup(scene, layer, settings):
        capture = pipeline.SequenceCapture(scene, layer, settings, pipeline.Timings())
        denoised = pipeline.run_frame(capture.frame(1))
    hit = denoised.mean[passes.AOV_DISTANCE][..., 0] > 0.0
    depth = denoised.mean["Depth"][..., 0]
    assert hit.mean() > 0.3
    # Metres from the camera, or no hit at sample 0 (edge pixels): never a mix of the two.
    assert np.all((depth < 100.0) | (depth == np.float32(1e10)))
    assert np.mean(depth[hit] < 100.0) > 0.9


@pytest.mark.parametrize("samples", [0, pipeline.MAX_SAMPLES_PER_FRAME + 1])
def test_a_sample_count_out_of_range_is_refused_by_both_capture_routes(samples: int) -> None:
    scene, layer = bpy.context.scene, bpy.context.scene.view_layers[0]
    settings = pipeline.Settings(samples_per_frame=samples)
    with pytest.raises(ValueError, match=f"samples per frame must be 1 to {pipeline.MAX_SAMPLES_PER_FRAME}"):
        pipeline.DenoiseRender(scene, layer, [1], settings)
    with pytest.raises(ValueError, match=f"samples per frame must be 1 to {pipeline.MAX_SAMPLES_PER_FRAME}"):
        pipeline.SequenceCapture(scene, layer, settings, pipeline.Timings())


def test_the_preroll_gives_the_first_frame_a_history_from_other_samples(tmp_path: Any) -> None:
    """Pre-roll P: the first frame is rendered P more times with other seeds and denoised as a
    still camera before the frame proper, which then has a history: its own samples are
    unchanged, its motion is zero and its history valid, it is closer to the reference (the
    median over seeds, and on most seeds), and the history carries on into the next frame,
    whose samples and motion are its own."""
    from conftest import CORE_AVAILABLE
    if not CORE_AVAILABLE:
        pytest.skip("the affinity core is not importable")
    scene = scenes.build_scene()
    scene.frame_set(1)

    def high_spp(s: Any) -> None:
        s.cycles.samples = REFERENCE_SPP
        s.cycles.seed = 1  # independent of the samples being judged

    reference = capture(scene, high_spp)["Combined"][..., :3]
    scene.cycles.samples = scenes.SPP
    spp = scenes.SPP

    def denoise_render(seed: int, preroll: int) -> pipeline.DenoiseRender:
        scene.cycles.seed = seed
        scene.render.filepath = str(tmp_path / f"seed{seed}_preroll{preroll}" / "frame_")
        job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1, 2],
                                     pipeline.Settings(samples_per_frame=spp, preroll_frames=preroll))
        job.keep_frames = True
        job.run()
        return job

    # Quality over six seeds: at 4 spp and 64x48 one seed's error swings by up to 4x, and one
    # firefly in a pre-roll frame can stay in the history (bpy 5.3.0, seed 0: 0.208 against
    # 0.122 without). Measured on bpy 5.0.1 with the extension's model: the default pre-roll
    # (one frame of 32 at 4 spp) takes the median relMSE to 0.80x and SMAPE to 0.78x of none's
    # (one frame of 16: 0.87x and 0.80x; docs/BLENDER.md, "Pre-roll").
    from affinity_core import metrics
    frames = pipeline.DEFAULT_PREROLL_FRAMES
    errors: dict[int, list[float]] = {0: [], frames: []}
    smapes: dict[int, list[float]] = {0: [], frames: []}
    jobs = {}
    for seed in range(6):
        for preroll in (0, frames):
            job = denoise_render(seed, preroll)
            errors[preroll].append(_relative_mse(job.results[0].denoised, reference))
            smapes[preroll].append(metrics.smape(job.results[0].denoised, reference))
            if seed == 0:
                jobs[preroll] = job
    plain, prerolled = jobs[0], jobs[frames]
    assert len(plain.timings.sub_renders) == 2 * spp
    assert len(prerolled.timings.sub_renders) == 2 * spp + frames * pipeline.automatic_preroll_samples(spp)
    first, first_plain = prerolled.results[0], plain.results[0]
    np.testing.assert_array_equal(first.frame_data["samples"], first_plain.frame_data["samples"])
    assert not first_plain.frame_data["valid"].any()
    assert first.frame_data["valid"].all() and not first.frame_data["motion"].any()
    error, error_plain = float(np.median(errors[frames])), float(np.median(errors[0]))
    print(f"frame 1: relMSE against {REFERENCE_SPP} spp, median of 6 seeds: pre-roll {error:.5f}, "
          f"none {error_plain:.5f}; per seed {errors}; SMAPE median {np.median(smapes[frames]):.4f} against "
          f"{np.median(smapes[0]):.4f}, per seed {smapes}")
    assert error < 0.95 * error_plain
    assert sum(with_preroll < without for with_preroll, without in zip(errors[frames], errors[0])) >= 4
    assert np.median(smapes[frames]) < 0.85 * np.median(smapes[0])
    assert sum(with_preroll < without for with_preroll, without in zip(smapes[frames], smapes[0])) >= 5
    # The next frame's samples, motion and validity are its own, as without a pre-roll.
    for key in ("samples", "motion", "valid"):
        np.testing.assert_array_equal(prerolled.results[1].frame_data[key], plain.results[1].frame_data[key])
    assert np.abs(prerolled.results[1].denoised - plain.results[1].denoised).mean() > 1e-4


def test_preroll_frames_have_their_own_sample_count(tmp_path: Any) -> None:
    """By default each pre-roll frame has 8 times the frames' own samples, 16 to 64
    (docs/BLENDER.md, "Pre-roll", has what that buys on the Cycles suite): 16 before frames of 2
    samples; the setting changes it; the frame's own samples stay its own. Streamed to the core
    (how a render runs) the 16-sample pre-roll frame before the 2-sample frame gives what the
    kept frames give, but for the depth normalisation (test_streamed_samples_give_...)."""
    assert (pipeline.DEFAULT_PREROLL_FRAMES, pipeline.AUTO_PREROLL_SAMPLES) == (1, 0)
    assert [pipeline.automatic_preroll_samples(s) for s in (1, 2, 4, 8, 16)] == [16, 16, 32, 64, 64]
    assert pipeline.Settings(samples_per_frame=4).preroll_sample_count() == 32
    assert pipeline.Settings(samples_per_frame=4, preroll_samples=5).preroll_sample_count() == 5
    scene = scenes.build_scene(frames=1)
    kept = {}
    for setting, expected in ((None, 16), (3, 3)):
        scene.render.filepath = str(tmp_path / f"samples{setting}" / "frame_")
        settings = pipeline.Settings(samples_per_frame=2, preroll_frames=1)
        if setting is not None:
            settings.preroll_samples = setting
        job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1], settings)
        job.keep_frames = True
        job.run()
        (preroll,) = job.results[0].preroll_data
        assert preroll["samples"].shape[2] == expected
        assert job.results[0].frame_data["samples"].shape[2] == 2
        # Every pre-roll sample is a sample of its own, with the frame's light on average: where
        # sub-renders are one sample of a set, the set must hold all of them (bpy 4.5 and later;
        # with the frames' set of 2, offsets 2-7 rendered the wrong samples).
        light = preroll["samples"][..., 0:3] + preroll["samples"][..., 3:6]
        for s in range(expected):
            for t in range(s):
                assert not np.array_equal(light[:, :, s], light[:, :, t]), (s, t)
        own = job.results[0].frame_data["samples"]
        own_light = (own[..., 0:3] + own[..., 3:6]).mean(2)
        assert abs(float((light.mean(2) / (1 + light.mean(2))).mean())
                   / float((own_light / (1 + own_light)).mean()) - 1) < 0.1
        assert len(job.timings.sub_renders) == expected + 2
        kept[setting] = job.results[0].denoised
    scene.render.filepath = str(tmp_path / "streamed" / "frame_")
    streamed = pipeline.DenoiseRender(scene, scene.view_layers[0], [1],
                                      pipeline.Settings(samples_per_frame=2, preroll_frames=1))
    streamed.run()
    assert streamed.results[0].frame_data is None and len(streamed.timings.sub_renders) == 16 + 2
    difference = np.abs(streamed.results[0].denoised - kept[None])
    assert difference.mean() <= 0.01 * np.abs(kept[None]).mean()
    assert np.abs(kept[3] - kept[None]).mean() > 1e-4  # the pre-roll's samples count


def run_with_one_preroll_frame(scene: Any, folder: Any) -> pipeline.DenoiseRender:
    """Frames 1-3 at 2 samples, a pre-roll of one 2-sample frame, the frames' data kept."""
    scene.render.filepath = str(folder / "frame_")
    job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1, 2, 3],
                                 pipeline.Settings(samples_per_frame=2, preroll_frames=1, preroll_samples=2))
    job.keep_frames = True
    job.run()
    return job


def test_a_camera_cut_starts_a_new_sequence_with_its_own_preroll(tmp_path: Any) -> None:
    """A cut (camera markers switch the scene camera at frame 2): frame 2 has no history from
    frame 1's camera and is pre-rolled like a first frame (zero motion, all valid after its
    pre-roll); frame 3 follows frame 2 as usual. Without the switch, frame 2 follows frame 1."""
    scene = scenes.build_scene(frames=3)
    first = scene.camera
    second = bpy.data.objects.new("Camera.cut", first.data.copy())
    scene.collection.objects.link(second)
    second.rotation_euler = (1.2, 0.0, 0.8)
    for frame, x in ((2, 4.0), (3, 4.3)):  # it moves too: frame 3 has motion from frame 2
        second.location = (x, -4.0, 2.5)
        second.keyframe_insert("location", frame=frame)

    def run(cut: bool) -> pipeline.DenoiseRender:
        scene.timeline_markers.clear()
        if cut:
            scene.timeline_markers.new("A", frame=1).camera = first
            scene.timeline_markers.new("B", frame=2).camera = second
        scene.camera = first
        return run_with_one_preroll_frame(scene, tmp_path / f"cut{cut}")

    cut, plain = run(True), run(False)
    assert [len(r.preroll_data) for r in cut.results] == [1, 1, 0]
    assert [len(r.preroll_data) for r in plain.results] == [1, 0, 0]
    after_cut = cut.results[1].frame_data
    assert after_cut["valid"].all() and not after_cut["motion"].any()
    assert len(cut.timings.sub_renders) == 3 * 2 + 2 * 2
    assert not plain.results[1].frame_data["valid"].all() or plain.results[1].frame_data["motion"].any()
    assert cut.results[2].frame_data["motion"].any()  # frame 3 moves on from frame 2


def test_a_jump_of_one_camera_is_a_cut_too(tmp_path: Any) -> None:
    """The same camera turned by 90 degrees at frame 2 (a keyframe, as cuts are often animated):
    frame 2 is pre-rolled like a first frame; turning by 2 degrees a frame, as the scene's
    camera does, is not a cut."""
    scene = scenes.build_scene(frames=3)
    camera = scene.camera

    def run(turn_at_frame_2: float) -> pipeline.DenoiseRender:
        for frame, turn in ((2, turn_at_frame_2), (3, turn_at_frame_2 + 2.0)):
            scene.frame_set(frame)
            camera.rotation_euler = (math.radians(70.0), 0.0, math.radians(turn))
            camera.keyframe_insert("rotation_euler", frame=frame)
        return run_with_one_preroll_frame(scene, tmp_path / f"turn{turn_at_frame_2}")

    turned, steady = run(90.0), run(2.0)
    assert [len(r.preroll_data) for r in turned.results] == [1, 1, 0]
    assert [len(r.preroll_data) for r in steady.results] == [1, 0, 0]
    after_jump = turned.results[1].frame_data
    assert after_jump["valid"].all() and not after_jump["motion"].any()


def test_a_preroll_out_of_range_is_refused() -> None:
    with pytest.raises(ValueError, match=f"pre-roll frames must be 0 to {pipeline.MAX_PREROLL_FRAMES}"):
        pipeline.Settings(preroll_frames=pipeline.MAX_PREROLL_FRAMES + 1).check()
    with pytest.raises(ValueError, match="pre-roll frames must be 0 to"):
        pipeline.Settings(preroll_frames=-1).check()
    for samples in (-1, pipeline.MAX_PREROLL_SAMPLES + 1):
        with pytest.raises(ValueError,
                           match=rf"pre-roll samples must be 0 \(automatic\) to {pipeline.MAX_PREROLL_SAMPLES}"):
            pipeline.Settings(preroll_samples=samples).check()
    from conftest import CORE_AVAILABLE
    if CORE_AVAILABLE:  # the bound restates the core's, which the extension must not need to import
        import affinity_core
        assert pipeline.MAX_PREROLL_SAMPLES == affinity_core.MAX_SPP
