#include "output_folder.h"

#include <system_error>

#include "affinity/error.h"

namespace affinity::cli {

namespace fs = std::filesystem;

OutputFolder::OutputFolder(const fs::path& path) : path_(path) {
    std::error_code error;
    made_ = !fs::exists(path, error);
    if (!error) fs::create_directories(path, error);
    if (error) throw Error("cannot create the output folder " + path.string() + ": " + error.message());
}

OutputFolder::~OutputFolder() {
    std::error_code ignored;
    if (made_ && fs::is_empty(path_, ignored)) fs::remove(path_, ignored);
}

}  // namespace affinity::cli
