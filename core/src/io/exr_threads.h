#pragma once
// OpenEXR compresses and decompresses a file's line blocks on its own worker threads only when
// told how many to use; by default it does all of it on the calling thread, which made reading a
// 1080p frame file take several times as long as denoising it. Frame files are now read on
// OpenMP's threads instead (frame_io.cpp:
// OpenEXR's workers buffer two blocks each); writes and image files still use the workers.

namespace affinity {

// Gives OpenEXR as many worker threads as OpenMP would use (once per process; a count the
// program set itself is left alone). Called before a frame file is written and before an image
// file is opened.
void useExrWorkerThreads();

}  // namespace affinity
