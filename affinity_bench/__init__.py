"""The evaluation benchmark, a development tool of this repository (not part of the `affinity_core`
wheel): ``python -m affinity_bench --out DIR [--config full|tiny|cycles] ...`` from the
repository root, with the built module on the path (``PYTHONPATH=build/python:.``).

Runs the noisy input, OpenImageDenoise, SVGF, our model ladder and its ablations on the same
rendered sequences (the bundled failure-case scenes and held-out procedural seeds, or the Cycles
suite) at several sample counts, and writes results.csv, per_frame.csv, results.md and PNG
charts into DIR. docs/BENCHMARK.md describes every output and how each number is measured.
Speed at large frame sizes is another tool's: scripts/bench_denoiser.sh.

Modules: ``config`` (what a run covers), ``data`` (rendering and caching the sequences),
``methods`` (the compared methods), ``evaluate`` (running and measuring them), ``report``
(tables and charts), ``cycles`` (the Cycles suite's sequences and Blender's own denoiser).
"""

import pathlib

#: The repository this package lives in: the benchmark reads its models (core/models) from here.
REPOSITORY = pathlib.Path(__file__).resolve().parent.parent
