#!/usr/bin/env bash
# Runs a Windows executable under wine, for cargo as the runner of x86_64-pc-windows-gnu:
#
#   CARGO_TARGET_X86_64_PC_WINDOWS_GNU_RUNNER=tests/wine/run.sh \
#       cargo test --target x86_64-pc-windows-gnu -p ferrobus-proto
#
# Uses a private wine prefix (WINEPREFIX, default target/wine/prefix, made on first use), and
# puts beside the program the stand-in bcryptprimitives.dll that wine 8 lacks and Rust's
# standard library needs (processprng.c, built here with mingw-w64 when missing or stale).
# WINE names the wine binary (default /usr/lib/wine/wine64, Debian's wine64).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
out="${CARGO_TARGET_DIR:-$root/target}/wine"
dll="$out/bcryptprimitives.dll"
mkdir -p "$out"
if [ ! -f "$dll" ] || [ "$here/processprng.c" -nt "$dll" ] || [ "$here/bcryptprimitives.def" -nt "$dll" ]; then
    x86_64-w64-mingw32-gcc -shared -O2 -Wall -Wextra -Werror -o "$dll.tmp" \
        "$here/processprng.c" "$here/bcryptprimitives.def" -lbcrypt
    mv -f "$dll.tmp" "$dll"
fi

export WINEPREFIX="${WINEPREFIX:-$out/prefix}"
export WINEDEBUG="${WINEDEBUG:--all}"
# The DLL search path, as wine sees it (Z: is the Unix root): the stand-in is found like a
# system DLL.
export WINEPATH="Z:${out//\//\\}"
exec "${WINE:-/usr/lib/wine/wine64}" "$@"
