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

// A call abandoned because its interrupt check asked it to stop (Ctrl-C): not the input's fault.
class Interrupted : public Error {
public:
    explicit Interrupted(const std::string& message) : Error(message) {}
};

}  // namespace affinity
