"""Writes out/demo/summary.md from the render and denoise summaries of the demo run."""

import json
import pathlib
import sys

out = pathlib.Path(sys.argv[1])
render = json.loads((out / "frames" / "render_summary.json").read_text())
denoise = json.loads((out / "denoised" / "denoise_summary.json").read_text())
lines = [
    f"# Demo: {render['scene']}, {render['frames']} frames of {render['size'][0]}x{render['size'][1]} "
    f"at {render['spp']} spp (reference {render['reference_spp']} spp)",
    "",
    f"Rendering: {render['seconds']:.1f} s, {render['rays_per_second'] / 1e6:.1f} Mrays/s. "
    f"Denoising: {denoise['milliseconds_per_frame']:.1f} ms per frame ({denoise['model']}).",
    "",
    "| frame | SMAPE noisy | SMAPE denoised | PSNR noisy (dB) | PSNR denoised (dB) |",
    "|---|---|---|---|---|",
]
for entry in denoise["per_frame"]:
    noisy, denoised = entry["noisy"], entry["denoised"]
    lines.append(f"| {entry['frame']} | {noisy['smape']:.4f} | {denoised['smape']:.4f} | "
                 f"{noisy['psnr']:.2f} | {denoised['psnr']:.2f} |")
(out / "summary.md").write_text("\n".join(lines) + "\n")
print("\n".join(lines))
print(f"\nimages: {out}/frames/*.png (noisy, reference), {out}/denoised/*.png; summary: {out}/summary.md")
