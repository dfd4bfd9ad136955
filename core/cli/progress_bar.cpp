#include "progress_bar.h"

#include <cstdio>

#include <unistd.h>

namespace affinity::cli {

ProgressBar::ProgressBar(std::string label)
    : label_(std::move(label)), interactive_(isatty(fileno(stderr)) != 0), start_(std::chrono::steady_clock::now()) {}

void ProgressBar::update(double fraction) {
    int percent = int(fraction * 100.0);
    if (!interactive_ || percent == lastPercent_) return;
    lastPercent_ = percent;
    constexpr int kWidth = 30;
    int filled = percent * kWidth / 100;
    double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    std::fprintf(stderr, "\r%s [%.*s%*s] %3d%% %6.1fs", label_.c_str(), filled, "##############################",
                 kWidth - filled, "", percent, seconds);
    std::fflush(stderr);
}

void ProgressBar::finish(const std::string& summary) {
    double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    if (interactive_) std::fprintf(stderr, "\r\033[K");
    std::fprintf(stderr, "%s: %s (%.2f s)\n", label_.c_str(), summary.c_str(), seconds);
}

}  // namespace affinity::cli
