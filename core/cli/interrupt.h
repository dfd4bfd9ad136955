#pragma once
// Ctrl-C, SIGTERM and SIGHUP for the commands: the first signal asks the command to stop at its
// next safe point (between a frame's steps, never inside a file write), so that finished frames
// stay, no temporary file is left and the summary says what was done; a second signal ends the
// process at once (exit 128 + signal), removing the temporary files being written.
#include <string>

namespace affinity::cli {

void installInterruptHandlers();
// Whether a signal asked the command to stop.
bool interruptRequested();
// Says on stderr that `command` stopped after `done` of `total` frames, kept in `folder`, and
// returns the exit status for the signal that asked (128 + its number, 130 if none did).
int reportInterrupted(const char* command, long long done, long long total, const std::string& folder);

}  // namespace affinity::cli
