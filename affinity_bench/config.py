"""What a benchmark run covers: sequences, sizes, sample counts."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

#: The bundled scenes (samples/scenes), each built around one place where denoisers fail.
FAILURE_CASE_SCENES = ("disocclusion", "fine_texture", "fireflies", "glossy", "low_light", "refraction",
                       "thin_geometry")
#: Procedural seeds never used in training (training uses 1000-1099 and 20000-21308, validation
#: 9000-9003; docs/TRAINING.md).
HELD_OUT_SEEDS = (9100, 9101, 9102, 9103)
#: Seed of the bundled scenes' renders.
SCENE_RENDER_SEED = 7
#: Added to a sequence's seed for its second, independent reference (the reference noise floor).
SECOND_REFERENCE_SEED_OFFSET = 1_000_000


@dataclass(frozen=True)
class Sequence:
    name: str           # used in file names and tables
    scene: str          # the `affinity render --scene` argument
    seed: int           # the `affinity render --seed` argument
    failure_case: bool  # a bundled failure-case scene (gets per-frame temporal charts and crops)


@dataclass(frozen=True)
class Config:
    name: str
    sequences: tuple[Sequence, ...]
    width: int
    height: int
    frames: int
    spp: tuple[int, ...]             # input sample counts of the main comparison (every method)
    equal_time_spp: tuple[int, ...]  # sample counts of OpenImageDenoise (and noisy) in the equal-time chart
    reference_spp: int
    chart_spp: int                   # sample count of the crops
    timing_runs: int                 # each sequence is denoised this often; per frame the fastest call counts
    # Render a second reference with other random numbers and score it against the first: the
    # error any output has at best, since the references are noisy too.
    reference_noise: bool = True

    @property
    def render_spp(self) -> int:
        """Samples rendered per pixel; every smaller count uses the first samples of each pixel."""
        return max(self.spp + self.equal_time_spp)

    def with_overrides(self, **changes: object) -> Config:
        return dataclasses.replace(self, **changes)


def _scene(name: str) -> Sequence:
    return Sequence(name, name, SCENE_RENDER_SEED, True)


def _procedural(seed: int) -> Sequence:
    return Sequence(f"procedural_{seed}", f"procedural:{seed}", seed, False)


FULL = Config(
    name="full",
    sequences=tuple(_scene(n) for n in FAILURE_CASE_SCENES) + tuple(_procedural(s) for s in HELD_OUT_SEEDS),
    width=128,
    height=96,
    frames=8,
    spp=(2, 4, 8),
    equal_time_spp=(2, 4, 8, 16, 32),
    reference_spp=1024,
    chart_spp=4,
    timing_runs=3,
)

# For CI: every stage and output of the full run, on two failure-case scenes at a stamp size.
TINY = Config(
    name="tiny",
    sequences=(_scene("glossy"), _scene("disocclusion")),
    width=48,
    height=32,
    frames=3,
    spp=(2, 4),
    equal_time_spp=(2, 4, 8),
    reference_spp=64,
    chart_spp=4,
    timing_runs=2,
)

#: Seeds of the Cycles suite's validation scenes (training/cycles/make_data.py --val-seeds),
#: never trained on.
CYCLES_VALIDATION_SEEDS = tuple(range(9000, 9006))

# Blender's Cycles through the extension's capture path (cycles.py): the sequences are
# read from the cache that training/cycles/make_data.py fills, never rendered here; size,
# frames and reference samples are the ones that command used.
CYCLES = Config(
    name="cycles",
    sequences=tuple(Sequence(f"cycles_{s:05d}", "cycles", s, False) for s in CYCLES_VALIDATION_SEEDS),
    width=160,
    height=96,
    frames=8,
    spp=(2, 4, 8),
    equal_time_spp=(2, 4, 8),
    reference_spp=512,
    chart_spp=4,
    timing_runs=2,
)

CONFIGS = {c.name: c for c in (FULL, TINY, CYCLES)}
