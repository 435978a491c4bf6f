#!/usr/bin/env bash
# scripts/image-root.sh - the root of the container image (Dockerfile): what is copied onto the
# distroless base, laid out in a folder.
#
#   usr/bin/ferrobus                       the binary
#   usr/share/ferrobus/profiles/*.toml     the built-in device profiles, to copy from
#   usr/share/doc/ferrobus/README.md
#   etc/ferrobus/                          where the plant or lines file is mounted
#   var/lib/ferrobus/                      the bridge's store (a volume; the image's user owns it)
#
#   scripts/image-root.sh --bin PATH --out DIR
#
# The Dockerfile runs it on the binary it built; the tests run it on theirs.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
usage() {
    echo "image-root.sh: $1 (usage: scripts/image-root.sh --bin PATH --out DIR)" >&2
    exit 2
}
bin=""
out=""
while [ $# -gt 0 ]; do
    case "$1" in
    --bin | --out) [ $# -ge 2 ] || usage "$1 needs a value" ;;&
    --bin) bin="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    *) usage "unknown argument $1" ;;
    esac
done
[ -n "$bin" ] && [ -n "$out" ] || usage "--bin and --out are needed"
[ -x "$bin" ] || { echo "image-root.sh: $bin is not an executable" >&2; exit 2; }

mkdir -p "$out/usr/bin" "$out/usr/share/ferrobus/profiles" "$out/usr/share/doc/ferrobus" \
    "$out/etc/ferrobus" "$out/var/lib/ferrobus"
install -m 0755 "$bin" "$out/usr/bin/ferrobus"
find "$root/crates" -path '*/profiles/*.toml' -not -path '*/target/*' -exec install -m 0644 {} "$out/usr/share/ferrobus/profiles/" \;
install -m 0644 "$root/README.md" "$out/usr/share/doc/ferrobus/README.md"
