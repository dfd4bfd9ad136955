"""The table of scripts/cycles_draws.sh: each method's scores on several draws of the Cycles
suite's noise, and per scene how far the extension's model stands from Blender's own denoiser
once the luck of one draw is averaged out.

    .venv/bin/python scripts/cycles_draws_table.py OUT [--command TEXT]

Reads OUT/draw<k>/results.csv and OUT/draw<k>/cvvdp.csv (k = 0, 1, ...) and writes OUT/draws.md.
The difference's standard error is the spread of the per-draw differences over the square root
of their count: where the mean difference is smaller than about twice it, the suite cannot tell
the two methods apart on that scene.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import pathlib
import sys

OURS = "ours-extension+preroll"
BLENDER = "blender-oidn"
METHODS = (OURS, "oidn", BLENDER)
MEASURES = (("smape", "SMAPE"), ("flip", "FLIP"), ("temporal_error_tonemapped", "tone-mapped temporal error"),
            ("brightness", "brightness"))

# (draw, method, sequence, spp) -> {measure: value}
Scores = dict[tuple[int, str, str, int], dict[str, float]]


def read_draws(out: pathlib.Path) -> tuple[Scores, int]:
    """Every draw's scores and the number of draws (folders draw0, draw1, ... in order)."""
    scores: Scores = {}
    draw = 0
    while (out / f"draw{draw}").is_dir():
        folder = out / f"draw{draw}"
        for name in ("results.csv", "cvvdp.csv"):
            if not (folder / name).is_file():
                raise SystemExit(f"cycles_draws_table: {folder / name} is missing")
        with open(folder / "results.csv", newline="") as handle:
            for row in csv.DictReader(handle):
                key = (draw, row["method"], row["sequence"], int(row["spp"]))
                scores.setdefault(key, {}).update({m: float(row[m]) for m, _ in MEASURES})
        with open(folder / "cvvdp.csv", newline="") as handle:
            for row in csv.DictReader(handle):
                key = (draw, row["method"], row["sequence"], int(row["spp"]))
                scores.setdefault(key, {})["jod"] = float(row["cvvdp_jod"])
        draw += 1
    if draw == 0:
        raise SystemExit(f"cycles_draws_table: no draw0 folder in {out}")
    return scores, draw


def mean(values: list[float]) -> float:
    return sum(values) / len(values)


def standard_error(values: list[float]) -> float:
    if len(values) < 2:
        return math.nan
    m = mean(values)
    return math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1) / len(values))


def table(scores: Scores, draws: int, command: str) -> str:
    sequences = sorted({key[2] for key in scores})
    counts = sorted({key[3] for key in scores})

    def value(draw: int, method: str, sequence: str, spp: int, measure: str) -> float:
        try:
            return scores[(draw, method, sequence, spp)][measure]
        except KeyError:
            raise SystemExit(f"cycles_draws_table: draw {draw} lacks {measure} of {method} on {sequence} "
                             f"at {spp} spp") from None

    lines = [f"# The Cycles suite over {draws} draws of its noise", "",
             f"Command: `{command}`. Draw 0 is the suite's own cache; each other draw captured the "
             "same scenes' inputs, pre-roll and Blender's own denoiser again from another seed "
             "(`make_data.py --input-draw N --references-from DATA0`), scored against the same "
             "references. Methods: `ours-extension+preroll` (the extension's model with its "
             "pre-roll), `oidn` (OpenImageDenoise through pyoidn on the same passes), `blender-oidn` "
             "(Cycles with its own OpenImageDenoise, as users get it).", "",
             "## ColorVideoVDP per scene: ours against Blender's own denoiser", "",
             "JOD per draw (ours / Blender's), then the mean over draws of ours minus Blender's, its "
             "standard error, and in how many draws ours is ahead.", "",
             "| sequence | spp | " + " | ".join(f"draw {d}" for d in range(draws))
             + " | mean difference | standard error | ours ahead |",
             "|---|---:|" + "---|" * draws + "---:|---:|---:|"]
    for sequence in sequences:
        for spp in counts:
            ours = [value(d, OURS, sequence, spp, "jod") for d in range(draws)]
            blender = [value(d, BLENDER, sequence, spp, "jod") for d in range(draws)]
            differences = [o - b for o, b in zip(ours, blender)]
            cells = [f"{o:.2f} / {b:.2f}" for o, b in zip(ours, blender)]
            lines.append(f"| {sequence} | {spp} | " + " | ".join(cells)
                         + f" | {mean(differences):+.3f} | {standard_error(differences):.3f} | "
                           f"{sum(d > 0 for d in differences)} of {draws} |")
    lines += ["", "## Means over the scenes, per draw and over draws", "",
              "| measure | spp | " + " | ".join(f"`{m}`" for m in METHODS) + " |",
              "|---|---:|" + "---|" * len(METHODS)]
    for measure, label in (("jod", "ColorVideoVDP JOD"), *MEASURES):
        for spp in counts:
            cells = []
            for method in METHODS:
                per_draw = [mean([value(d, method, s, spp, measure) for s in sequences]) for d in range(draws)]
                cells.append(f"{mean(per_draw):.4f} ({' / '.join(f'{v:.4f}' for v in per_draw)})")
            lines.append(f"| {label} | {spp} | " + " | ".join(cells) + " |")
    lines += ["", "Each cell: the mean over draws, then each draw's mean over the scenes."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=pathlib.Path, help="the OUT folder of scripts/cycles_draws.sh")
    parser.add_argument("--command", default=" ".join(sys.argv), help="the command to name in the table")
    args = parser.parse_args(argv)
    scores, draws = read_draws(args.out)
    text = table(scores, draws, args.command)
    temporary = args.out / "draws.md.tmp"
    temporary.write_text(text)
    os.replace(temporary, args.out / "draws.md")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
