#pragma once
// Writing plain images for people: float RGB EXR and tone-mapped 8-bit PNG. Atomic writes.
#include <string>

namespace affinity {

// rgb: width * height * 3 linear floats, row-major, top row first.
void writeRgbExr(const std::string& path, int width, int height, const float* rgb);
// Tone maps linear radiance (exposure scale, then x / (1 + x) per channel, then sRGB encoding).
void writeTonemappedPng(const std::string& path, int width, int height, const float* rgb, float exposure = 1.0f);

}  // namespace affinity
