#pragma once
// Ctrl-C, SIGTERM and SIGHUP for the commands: the first signal asks the command to stop at its
// next safe point (between a frame's steps, never inside a file write), so that finished frames
// stay, no temporary file is left and the summary says what was done; a second signal ends the
// process at once (exit 128 + signal), removing the temporary files being written.
namespace affinity::cli {

void installInterruptHandlers();
// Whether a signal asked the command to stop.
bool interruptRequested();
// The exit status for the signal that asked (128 + its number), 130 if none did.
int interruptedExitStatus();

}  // namespace affinity::cli
