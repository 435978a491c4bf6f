#!/usr/bin/env bash
# .ci/setup-cross.sh - what checking and running the other platforms needs, installed once.
#
#   rustup targets   x86_64-pc-windows-gnu, x86_64-apple-darwin (clippy for both)
#   apt              gcc-mingw-w64-x86-64 (the Windows linker, and the wine shim of tests/wine/),
#                    wine64 (runs the Windows tests and binary), clang and llvm (criterion's
#                    alloca compiles one C file for every target, macOS included: clang does
#                    that without an SDK, -ffreestanding, and nothing is linked by a check)
#
# Idempotent; runs as root, or via sudo for apt-get. With CI=true a missing piece fails here;
# without, it is a WARNING and the steps that need it fail later with the tool's own message.
set -euo pipefail

APT_PACKAGES=(gcc-mingw-w64-x86-64 wine64 clang llvm)
export DEBIAN_FRONTEND=noninteractive
IN_CI=false
case "${CI:-}" in true | TRUE | True | 1 | yes) IN_CI=true ;; esac
log() { printf 'setup-cross: %s\n' "$*" >&2; }
fail() {
    if $IN_CI; then
        log "ERROR: $* (CI=true: failing)"
        exit 1
    fi
    log "WARNING: $*"
}

rustup target add x86_64-pc-windows-gnu x86_64-apple-darwin >/dev/null 2>&1 ||
    fail "rustup target add x86_64-pc-windows-gnu x86_64-apple-darwin failed"

SUDO=()
[ "$(id -u)" -eq 0 ] || SUDO=(sudo -n)
NEED=()
for p in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || NEED+=("$p")
done
if [ "${#NEED[@]}" -gt 0 ]; then
    log "apt-get install ${NEED[*]}"
    if ! { "${SUDO[@]}" apt-get update -qq &&
        "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
            "${NEED[@]}" >/dev/null; }; then
        fail "apt-get install ${NEED[*]} failed"
    fi
fi
echo "cross: $(x86_64-w64-mingw32-gcc -dumpfullversion 2>/dev/null || echo 'mingw missing'), $(/usr/lib/wine/wine64 --version 2>/dev/null || echo 'wine missing'), clang $(clang -dumpversion 2>/dev/null || echo missing)"
