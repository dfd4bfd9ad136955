#pragma once
// Luminance of linear RGB with the Rec. 709 weights, for the stages that judge light by one
// number (SVGF's edge-stopping, the light restoration).

namespace affinity {

inline constexpr float kLumaR = 0.2126f, kLumaG = 0.7152f, kLumaB = 0.0722f;

inline float luminance(const float* rgb) { return kLumaR * rgb[0] + kLumaG * rgb[1] + kLumaB * rgb[2]; }

}  // namespace affinity
