#pragma once
// Atomic file replacement: readers of `path` see either the old file or the complete new one,
// never a partial write, even when the writer throws or the process dies mid-write.
#include <functional>
#include <string>

namespace affinity {

// Calls `write` with the name of a fresh temporary file in the same folder as `path`
// ("<path>.tmp-<pid>-<counter>", so it never matches a frame file name), flushes it to disk,
// then renames it over `path`. If `write` or any later step throws, the temporary file is
// removed and the exception propagates. Failures of the helper itself (sync, rename) throw
// affinity::Error naming the files involved.
void writeAtomically(const std::string& path, const std::function<void(const std::string& temporaryPath)>& write);

// Removes every temporary file a writeAtomically() call is writing at this moment, for a
// signal handler about to end the process: async-signal-safe (unlink only). Files with paths
// longer than 4 KiB, or more than 16 at once, are not tracked.
void removeTemporaryFilesNow() noexcept;

}  // namespace affinity
