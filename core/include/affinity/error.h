#pragma once
// The one exception type the library throws for bad input or failed I/O. Its message names
// the file or buffer and what is wrong; the Python and CLI boundaries pass it on unchanged.
#include <stdexcept>
#include <string>

namespace affinity {

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace affinity
