#!/usr/bin/env bash
# Checks that every C++ file of core/, training/, python_bindings/, bench/, tests/cpp and
# tests/fuzz is formatted as .clang-format says: exits 0 when clang-format would change nothing,
# 1 and names each file it would change otherwise, 2 when clang-format is missing.
#   scripts/check_format.sh            (run from anywhere; checks the repository it lives in)
# Fix what it names with `clang-format -i FILE...`. The style was applied with clang-format 14
# (Debian 12's `clang-format` package); other versions may format a few constructs otherwise.
# CLANG_FORMAT names another binary.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
clang_format=${CLANG_FORMAT:-clang-format}
if ! command -v "$clang_format" > /dev/null; then
  echo "check_format: $clang_format not found (Debian: apt-get install clang-format)" >&2
  exit 2
fi
version=$("$clang_format" --version)
case "$version" in
  *"version 14."*) ;;
  *) echo "check_format: note: the tree was formatted with clang-format 14; this is: $version" >&2 ;;
esac

# Tracked files and new ones not ignored, so that a file not yet added is checked too.
mapfile -t files < <(git ls-files --cached --others --exclude-standard -- \
  core training python_bindings bench tests/cpp tests/fuzz |
  grep -E '\.(c|cc|cpp|cxx|h|hh|hpp|hxx|inl|ipp)$' | sort -u |
  while IFS= read -r f; do [[ -f $f ]] && printf '%s\n' "$f"; done)
if [[ ${#files[@]} -eq 0 ]]; then
  echo "check_format: no C++ files found under $root" >&2
  exit 2
fi

status=0
output=$("$clang_format" --dry-run --Werror --style=file "${files[@]}" 2>&1) || status=$?
if [[ $status -eq 0 ]]; then
  echo "check_format: ${#files[@]} C++ files formatted"
  exit 0
fi
mapfile -t bad < <(printf '%s\n' "$output" | sed -n 's/^\([^:]*\):[0-9]*:[0-9]*: error: code should be clang-formatted.*/\1/p' | sort -u)
if [[ ${#bad[@]} -eq 0 ]]; then
  # clang-format failed for another reason (an unreadable .clang-format, a file it cannot parse).
  printf '%s\n' "$output" >&2
  exit 1
fi
echo "check_format: ${#bad[@]} of ${#files[@]} C++ files are not formatted (clang-format -i FILE... fixes them):" >&2
printf '  %s\n' "${bad[@]}" >&2
exit 1
