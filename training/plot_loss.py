#!/usr/bin/env python3
"""Plots affinity_train's loss.csv: training and validation loss, and validation SMAPE against the
noisy input's. Usage: plot_loss.py RUN_DIR/loss.csv [more.csv ...] --out loss.png
Several CSVs (a run and its continuation) are drawn as one curve, steps offset in order."""
import argparse
import csv
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read(paths):
    rows, offset = [], 0
    for path in paths:
        last = 0
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                values = {k: float(v) for k, v in row.items()}
                last = values["step"]
                values["step"] += offset
                rows.append(values)
        offset += last
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("csv", nargs="+")
    parser.add_argument("--out", required=True)
    parser.add_argument("--title", default="affinity_train")
    args = parser.parse_args()
    rows = read(args.csv)
    step = [r["step"] for r in rows]

    def series(key):
        return [r[key] if not math.isnan(r[key]) else None for r in rows]

    fig, (loss_ax, smape_ax) = plt.subplots(1, 2, figsize=(11, 4))
    train = [(s, v) for s, v in zip(step, series("train_loss")) if v is not None]
    if train:
        loss_ax.plot(*zip(*train), label="train loss (mean over the interval)")
    loss_ax.plot(step, series("val_loss"), label="validation loss (SMAPE + 0.25 temporal)")
    loss_ax.set_xlabel("step")
    loss_ax.set_ylabel("loss")
    loss_ax.grid(alpha=0.3)
    loss_ax.legend()
    smape_ax.plot(step, series("val_smape"), label="validation SMAPE, denoised")
    smape_ax.plot(step, series("val_noisy_smape"), "--", label="validation SMAPE, noisy input")
    smape_ax.set_xlabel("step")
    smape_ax.set_ylabel("SMAPE")
    smape_ax.set_ylim(bottom=0)
    smape_ax.grid(alpha=0.3)
    smape_ax.legend()
    fig.suptitle(args.title)
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
