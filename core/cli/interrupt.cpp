#include "interrupt.h"

#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>

#include "affinity/atomic_file.h"

namespace affinity::cli {
namespace {

std::atomic<int> signalsReceived{0};
std::atomic<int> firstSignal{SIGINT};
static_assert(std::atomic<int>::is_always_lock_free, "read and written in a signal handler");

extern "C" void onSignal(int number) {
    if (signalsReceived.fetch_add(1) == 0) {
        firstSignal.store(number);
        return;
    }
    removeTemporaryFilesNow();
    ::_exit(128 + number);
}

}  // namespace

void installInterruptHandlers() {
    struct sigaction action {};
    action.sa_handler = onSignal;
    sigemptyset(&action.sa_mask);
    for (const int number : {SIGINT, SIGTERM, SIGHUP}) ::sigaction(number, &action, nullptr);
}

bool interruptRequested() { return signalsReceived.load() > 0; }

int reportInterrupted(const char* command, long long done, long long total, const std::string& folder) {
    std::fprintf(stderr, "\naffinity %s: interrupted after %lld of %lld frames; those are kept in %s\n", command, done,
                 total, folder.c_str());
    return 128 + firstSignal.load();
}

}  // namespace affinity::cli
