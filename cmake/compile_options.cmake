# Compile options shared by every target of the project (not by third-party code).
add_library(affinity_options INTERFACE)
target_compile_options(affinity_options INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
  # GCC 12 reports false -Wrestrict positives inside std::string concatenation at -O3
  # (clang has no such warning and rejects the flag).
  $<$<CXX_COMPILER_ID:GNU>:-Wno-restrict>
  -march=${AFFINITY_ARCH}
  # Without these the float loops do not vectorise (docs/METHOD.md section 12); we never rely on errno or traps.
  -fno-math-errno -fno-trapping-math)
if(AFFINITY_WERROR)
  target_compile_options(affinity_options INTERFACE -Werror)
endif()
if(AFFINITY_SANITIZE)
  target_compile_options(affinity_options INTERFACE
    -fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer)
  target_link_options(affinity_options INTERFACE -fsanitize=address,undefined)
endif()
