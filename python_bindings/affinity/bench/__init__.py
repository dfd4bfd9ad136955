"""The evaluation benchmark: ``python -m affinity.bench --out DIR [--config full|tiny] ...``.

Runs the noisy input, OpenImageDenoise, SVGF, our model ladder and its ablations on the same
rendered sequences (the bundled failure-case scenes and held-out procedural seeds) at several
sample counts, and writes results.csv, per_frame.csv, results.md, speed.csv, speed.md and PNG
charts into DIR. docs/BENCHMARK.md describes every output and how each number is measured.

Modules: ``config`` (what a run covers), ``data`` (rendering and caching the sequences),
``methods`` (the compared methods), ``evaluate`` (running and measuring them), ``report``
(tables and charts), ``speed`` (large-frame speed and memory, one process per method).
"""
