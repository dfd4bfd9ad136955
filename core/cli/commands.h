#pragma once
// The subcommands of the `affinity` program. Each takes the arguments after its name and
// returns the process exit code; errors are thrown as affinity::Error.
#include <string>
#include <vector>

namespace affinity::cli {

int renderCommand(const std::vector<std::string>& args);
int denoiseCommand(const std::vector<std::string>& args);

}  // namespace affinity::cli
