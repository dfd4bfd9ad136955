#pragma once
// A pre-check of an OpenEXR file's header, run before OpenEXR's C++ library parses it.
// OpenEXR 3.1 trusts the sizes in a header: a corrupt attribute size or data window makes it
// allocate (and fill) gigabytes for a file of a few kilobytes before it notices anything is
// wrong (found by fuzzing readFrame). This walks the header exactly as that library will and
// rejects what would make it allocate more than the file can justify.
#include <string>

namespace affinity {

// Frame files never need more pixels per side than this; larger data windows are rejected
// before any buffer is sized from them.
constexpr int kMaxExrImageSide = 16384;

// Throws affinity::Error (without the path; the caller adds it) unless the file is a
// single-part scanline OpenEXR file whose every header attribute has the size its type
// needs and fits in the file, whose data window is at most kMaxExrImageSide per side, and
// whose line offset table fits in the file.
void checkExrHeader(const std::string& path);

}  // namespace affinity
