#pragma once
// OpenEXR compresses and decompresses a file's line blocks on its own worker threads only when
// told how many to use; by default it does all of it on the calling thread. A 1080p frame file
// of 4 samples per pixel (600 MB of floats, PIZ) took 3.7-4.9 s to read that way, five times
// the time to denoise it.

namespace affinity {

// Gives OpenEXR as many worker threads as OpenMP would use (once per process; a count the
// program set itself is left alone). Called before every frame or image file is opened.
void useExrWorkerThreads();

}  // namespace affinity
