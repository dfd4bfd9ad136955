#pragma once
// A one-line progress bar on stderr, redrawn in place; silent when stderr is not a terminal
// except for a final line, so logs stay readable.
#include <chrono>
#include <string>

namespace affinity::cli {

class ProgressBar {
public:
    explicit ProgressBar(std::string label);
    void update(double fraction);  // 0..1
    void finish(const std::string& summary);

private:
    std::string label_;
    bool interactive_;
    int lastPercent_ = -1;
    std::chrono::steady_clock::time_point start_;
};

}  // namespace affinity::cli
