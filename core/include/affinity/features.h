#pragma once
// The per-sample feature schema: the contract between every producer of frames (the Embree
// renderer, the Blender adapter, files on disk) and every consumer (denoiser, training,
// baselines, metrics). See docs/FEATURES.md for what each channel means.
#include <array>
#include <cstddef>
#include <string_view>

namespace affinity {

// A group of consecutive channels in a sample's 18 floats.
struct FeatureGroup {
    std::string_view name;        // used in EXR channel names: "<name>.<component>"
    int offset;                   // first channel inside the sample
    int count;                    // number of channels
    std::string_view components;  // one letter per channel, e.g. "RGB", "XYZ"
    float minValue, maxValue;     // documented range (inclusive); radiance/depth are open above
};

// Channel indices inside one sample.
namespace channel {
inline constexpr int kDiffuse = 0;          // 3: diffuse radiance, linear, >= 0
inline constexpr int kSpecular = 3;         // 3: specular (= not diffuse) radiance, linear, >= 0
inline constexpr int kNormal = 6;           // 3: world-space unit shading normal, 0 on a miss
inline constexpr int kDepth = 9;            // 1: camera distance along the path, 0 on a miss
inline constexpr int kAlbedo = 10;          // 3: reflectance in [0, 1]
inline constexpr int kRoughness = 13;       // 1: linear roughness in [kRoughnessFloor, 1]
inline constexpr int kEmissive = 14;        // 1: flag, first non-specular vertex emits
inline constexpr int kMetallic = 15;        // 1: flag, conductor
inline constexpr int kTransmissive = 16;    // 1: flag, path transmitted through a dielectric
inline constexpr int kSpecularBounce = 17;  // 1: flag, first camera vertex was a delta interaction
}  // namespace channel

inline constexpr int kFeatureCount = 18;
// The network's depth normalisation (docs/MODEL.md section 1) averages the depths of every
// kDepthScaleRowStep-th image row, starting at row 0: a quarter of the input to read.
inline constexpr int kDepthScaleRowStep = 4;
// The network's exposure normalisation (docs/MODEL.md section 1): a sequence whose key (the
// geometric mean of the mean luminance in squares of kExposureBin x kExposureBin pixels of the
// rows the depth scale reads, squares darker than kExposureDarkBin x the mean square left out)
// lies outside [kExposureKeyLow, kExposureKeyHigh] has its radiance scaled onto the nearer end
// before the network sees it; inside, it is left as it is. The range is the 1st to 99th
// percentile of the training sequences' keys (data-f10, 158 lit sequences: 0.0013 and 0.64):
// brightnesses the network learnt on stay what they were.
inline constexpr int kExposureBin = 16;
inline constexpr double kExposureKeyLow = 0.0013, kExposureKeyHigh = 0.64;
inline constexpr double kExposureDarkBin = 1e-4;
// The factor on the radiance of a sequence of this key (> 0).
inline constexpr double exposureForKey(double key) {
    return key < kExposureKeyLow ? kExposureKeyLow / key : key > kExposureKeyHigh ? kExposureKeyHigh / key : 1.0;
}
inline constexpr float kRoughnessFloor = 0.02f;
// Radiance above this reads as invalid (0, and counted) like NaN, Inf and negative values: no
// light comes near it (a sun's disc is about 1e9), and sums of kMaxSpp such samples, filtered,
// stay far inside the float range. Four samples of 9e37 once summed to Inf, and Inf - Inf spread
// NaN over a quarter of the frame.
inline constexpr float kMaxRadiance = 1e20f;

inline constexpr std::array<FeatureGroup, 10> kFeatureGroups{{
    {"diffuse", channel::kDiffuse, 3, "RGB", 0.0f, 3.4e38f},
    {"specular", channel::kSpecular, 3, "RGB", 0.0f, 3.4e38f},
    {"normal", channel::kNormal, 3, "XYZ", -1.0f, 1.0f},
    {"depth", channel::kDepth, 1, "Z", 0.0f, 3.4e38f},
    {"albedo", channel::kAlbedo, 3, "RGB", 0.0f, 1.0f},
    {"roughness", channel::kRoughness, 1, "Y", 0.0f, 1.0f},
    {"emissive", channel::kEmissive, 1, "Y", 0.0f, 1.0f},
    {"metallic", channel::kMetallic, 1, "Y", 0.0f, 1.0f},
    {"transmissive", channel::kTransmissive, 1, "Y", 0.0f, 1.0f},
    {"specular_bounce", channel::kSpecularBounce, 1, "Y", 0.0f, 1.0f},
}};

// "diffuse.R", "normal.X", ... for channel index 0..17.
std::string featureChannelName(int channelIndex);

// True for the four binary flag channels.
constexpr bool isFlagChannel(int channelIndex) { return channelIndex >= channel::kEmissive; }

}  // namespace affinity
