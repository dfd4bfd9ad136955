#pragma once
// The output folder of a command: made only once the run's inputs are checked, and taken away
// again when a run that made it fails before writing anything into it.
#include <filesystem>

namespace affinity::cli {

class OutputFolder {
public:
    // Makes `path` and its missing parents; throws affinity::Error naming the folder and the
    // reason when it cannot (an unwritable parent is the user's to fix, not an internal error).
    explicit OutputFolder(const std::filesystem::path& path);
    // Removes the folder if this run made it and it is still empty (a failed or interrupted run
    // that wrote nothing leaves nothing behind).
    ~OutputFolder();
    OutputFolder(const OutputFolder&) = delete;
    OutputFolder& operator=(const OutputFolder&) = delete;

    const std::filesystem::path& path() const { return path_; }

private:
    std::filesystem::path path_;
    bool made_ = false;
};

}  // namespace affinity::cli
