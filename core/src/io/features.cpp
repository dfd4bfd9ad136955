#include "affinity/features.h"

#include <string>

#include "affinity/error.h"

namespace affinity {

std::string featureChannelName(int channelIndex) {
    for (const FeatureGroup& group : kFeatureGroups) {
        if (channelIndex >= group.offset && channelIndex < group.offset + group.count) {
            return std::string(group.name) + "." + group.components[channelIndex - group.offset];
        }
    }
    throw Error("feature channel index " + std::to_string(channelIndex) + " is outside 0.." +
                std::to_string(kFeatureCount - 1));
}

}  // namespace affinity
