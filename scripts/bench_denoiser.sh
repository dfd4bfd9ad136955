#!/usr/bin/env bash
# Denoiser speed and memory per model size at one frame size, against OpenImageDenoise on the
# same machine in the same run: bench_denoiser (core, C++) for the tiny and small (built-in)
# models and for the paper-sized network (random weights: speed does not depend on their
# values; needs the training build for affinity_model_tool), then pyoidn on an input of the
# same size, before the first model and after each one. Prints a markdown table with each stage's
# median milliseconds.
#   scripts/bench_denoiser.sh [WIDTHxHEIGHT] [SPP]        (default 1920x1080, 4)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
size=${1:-1920x1080}
spp=${2:-4}
build=${AFFINITY_BUILD:-$root/build}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# BENCH_JSON=FILE keeps the per-model results (one JSON object per line) for scripts/model_ladder.py.
json_out=${BENCH_JSON:-}
# BENCH_FRAMES=N (default 8) frames per model, the first untimed: medians of 7 steady the
# numbers on a shared machine.
# Idle OpenMP workers sleep instead of spinning, so that back-to-back runs do not slow each other.
export OMP_WAIT_POLICY=passive

# "<label>=<model file>[=lend|stream|avx2|bf16]": lend makes each frame's samples in bands the
# denoiser lends (Denoiser::sampleBands, as `affinity denoise` reads frame files), whose memory
# serves the later stages once embedded; stream feeds the frame one sample at a time
# (Denoiser::addSamples, as the Blender extension does), so one sample's features are held;
# avx2 runs the convolutions' AVX2 kernel where the CPU would pick AVX-512 (the same numbers
# bit for bit: the rows show what the wider kernel buys on this machine, in the same run); bf16
# takes the convolutions' products in bfloat16 (affinity/precision.h; CPUs with AVX512-BF16).
models=("tiny=$root/core/models/tiny.affw" "small=")
# The ladder's largest trained rung (docs/TRAINING.md), where it is in the checkout.
[ -f "$root/core/models/medium.affw" ] && models+=("medium=$root/core/models/medium.affw")
models+=("tiny lent=$root/core/models/tiny.affw=lend" "small lent==lend")
models+=("tiny streamed=$root/core/models/tiny.affw=stream" "small streamed==stream")
if grep -q avx512f /proc/cpuinfo 2>/dev/null; then
  models+=("tiny, AVX2 kernel=$root/core/models/tiny.affw=avx2" "small, AVX2 kernel==avx2")
fi
if grep -q avx512_bf16 /proc/cpuinfo 2>/dev/null; then
  models+=("tiny, bf16=$root/core/models/tiny.affw=bf16" "small, bf16==bf16")
fi
if [ -x "$build/training/affinity_model_tool" ]; then
  "$build/training/affinity_model_tool" init --preset paper --seed 1 --out "$work/paper.affw" >/dev/null
  models+=("paper=$work/paper.affw")
fi
# OpenImageDenoise is timed before the first model and after each one: a model's baseline is the
# mean of the OIDN runs on either side of it, so a change of load on the shared machine during
# the run moves both sides of each ratio alike.
cat >"$work/oidn.py" <<'PY'
import json, os, resource, statistics, sys, time

import numpy as np
import pyoidn

width, height = map(int, sys.argv[1].split("x"))
rng = np.random.default_rng(1)
color = rng.random((height, width, 3), dtype=np.float32) * 2
albedo = rng.random((height, width, 3), dtype=np.float32)
normal = rng.standard_normal((height, width, 3)).astype(np.float32)
normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
times = []
for i in range(int(os.environ.get("BENCH_FRAMES", "8"))):
    start = time.perf_counter()
    pyoidn.denoise(color, albedo, normal, hdr=True)
    if i > 0:
        times.append(1000 * (time.perf_counter() - start))
print(json.dumps({"ms": statistics.median(times), "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
PY
time_oidn() { "$root/.venv/bin/python" "$work/oidn.py" "$size" >>"$work/oidn.jsonl"; }
time_oidn
for entry in "${models[@]}"; do
  IFS='=' read -r label file mode <<<"$entry"
  args=(--size "$size" --spp "$spp" --frames "${BENCH_FRAMES:-8}")  # median of all but the first
  [ -n "$file" ] && args+=(--model "$file")
  [ "$mode" = stream ] && args+=(--stream 1)
  [ "$mode" = lend ] && args+=(--lend 1)
  [ "$mode" = bf16 ] && args+=(--precision bf16)
  isa=${AFFINITY_CONV_ISA:-}
  [ "$mode" = avx2 ] && isa=avx2
  echo "{\"label\": \"$label\", \"result\": $(AFFINITY_CONV_ISA=$isa "$build/bench/bench_denoiser" "${args[@]}")}" >>"$work/results.jsonl"
  time_oidn
done
[ -n "$json_out" ] && cp "$work/results.jsonl" "$json_out"
PYTHONPATH=$build/python "$root/.venv/bin/python" - "$size" "$spp" "$work/results.jsonl" "$work/oidn.jsonl" <<'PY'
import json, statistics, sys

size, spp, results, oidn_runs = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
rows = [json.loads(line) for line in open(results)]
oidn = [json.loads(line) for line in open(oidn_runs)]
# Row i's baseline: the OIDN runs just before and just after it.
baselines = [(oidn[i]["ms"] + oidn[i + 1]["ms"]) / 2 for i in range(len(rows))]
oidn_ms = statistics.median(run["ms"] for run in oidn)
oidn_rss = max(run["peak_rss_mb"] for run in oidn)
stages = list(rows[0]["result"]["stage_ms"])
print(f"Denoiser speed at {size}, {spp} spp, 2 threads; OpenImageDenoise (pyoidn, colour + albedo + normal, "
      f"quality high) timed before the first model and after each one: a row's ratio is over the mean of "
      f"the OIDN runs on either side of it. Peak memory (MiB) includes the input: the "
      f"{rows[0]['result']['input_frame_mb']:.0f} MiB frame of per-sample features (in the lent rows, "
      "in the denoiser's own memory, which its later stages reuse), or one sample's features for the "
      "streamed rows.")
cpu = {}
for line in open("/proc/cpuinfo"):
    key, _, value = line.partition(":")
    cpu.setdefault(key.strip(), value.strip())
kernel = "AVX-512 (AVX2 in the rows that say so)" if "avx512f" in cpu.get("flags", "").split() else "AVX2"
print(f"CPU: {cpu.get('model name', '?')}, family {cpu.get('cpu family', '?')}, model {cpu.get('model', '?')}; "
      f"convolution kernel: {kernel}.\n")
print("| model | parameters | kFLOP/px | ms/frame | OIDN ms beside it | OIDN ms / ours | peak memory MiB | "
      + " | ".join(stages) + " |")
print("|---|---|---|---|---|---|---|" + "---|" * len(stages))
for row, baseline in zip(rows, baselines):
    r = row["result"]
    print(f"| {row['label']} | {r['parameters']:,} | {r['kflop_per_pixel']:.1f} | {r['ms_per_frame']:.0f} | "
          f"{baseline:.0f} | {baseline / r['ms_per_frame']:.2f}x | {r['peak_rss_mb']:.0f} | "
          + " | ".join(f"{r['stage_ms'][s]:.0f}" for s in stages) + " |")
print(f"| OpenImageDenoise 2.5 (high), median of its {len(oidn)} runs | | | {oidn_ms:.0f} | | 1.00x | {oidn_rss:.0f} | "
      + " | " * (len(stages) - 1) + " |")
order = ", ".join(str(round(run["ms"])) for run in oidn)
print(f"\nOIDN runs in order (ms): {order}")
print(f"load average at the end: {open('/proc/loadavg').read().split()[0]}")
PY
