#include "affinity/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <system_error>

#include "affinity/error.h"

namespace affinity {
namespace {

// The temporary files being written, for removeTemporaryFilesNow(). A slot is claimed, filled,
// then published (`ready`), so that a signal handler reads only whole paths.
struct TemporarySlot {
    std::atomic<bool> claimed{false};
    std::atomic<bool> ready{false};
    char path[4096];
};
TemporarySlot temporarySlots[16];

// Tracks `path` while it exists; a no-op where no slot is free or the path does not fit.
class TrackedTemporary {
public:
    explicit TrackedTemporary(const std::string& path) {
        if (path.size() >= sizeof(TemporarySlot::path)) return;
        for (TemporarySlot& slot : temporarySlots) {
            bool expected = false;
            if (!slot.claimed.compare_exchange_strong(expected, true)) continue;
            std::memcpy(slot.path, path.c_str(), path.size() + 1);
            slot.ready.store(true);
            slot_ = &slot;
            return;
        }
    }
    ~TrackedTemporary() {
        if (!slot_) return;
        slot_->ready.store(false);
        slot_->claimed.store(false);
    }
    TrackedTemporary(const TrackedTemporary&) = delete;
    TrackedTemporary& operator=(const TrackedTemporary&) = delete;

private:
    TemporarySlot* slot_ = nullptr;
};

std::string temporaryPathFor(const std::string& path) {
    // pid + counter keeps concurrent writers (threads or processes) from sharing a file.
    static std::atomic<unsigned long> counter{0};
    return path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

// fsync so that after a crash the renamed file is never seen with missing contents.
void syncFileToDisk(const std::string& name) {
    const int fd = ::open(name.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw Error("cannot open '" + name + "' to sync it: " + std::strerror(errno));
    const int result = ::fsync(fd);
    const int syncErrno = errno;
    ::close(fd);
    if (result != 0) throw Error("cannot sync '" + name + "' to disk: " + std::strerror(syncErrno));
}

}  // namespace

void writeAtomically(const std::string& path, const std::function<void(const std::string& temporaryPath)>& write) {
    const std::string temporary = temporaryPathFor(path);
    const TrackedTemporary tracked(temporary);
    try {
        write(temporary);
        syncFileToDisk(temporary);
        std::error_code error;
        std::filesystem::rename(temporary, path, error);
        if (error) {
            throw Error("cannot rename '" + temporary + "' to '" + path + "': " + error.message());
        }
    } catch (...) {
        std::error_code ignored;
        std::filesystem::remove(temporary, ignored);
        throw;
    }
    // The rename itself is durable only once the folder entry is synced. Best effort: the new
    // file is already in place, so failing here would misreport the write as failed.
    std::filesystem::path folder = std::filesystem::path(path).parent_path();
    if (folder.empty()) folder = ".";
    const int fd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd >= 0) {
        ::fsync(fd);
        ::close(fd);
    }
}

void removeTemporaryFilesNow() noexcept {
    for (TemporarySlot& slot : temporarySlots)
        if (slot.ready.load()) ::unlink(slot.path);
}

}  // namespace affinity
