#!/usr/bin/env bash
# scripts/deb.sh - the Debian package of ferrobus, made with dpkg-deb (no cargo-deb: dpkg-deb is
# on every Debian system already, where cargo-deb is minutes of building in CI; the layout
# below is all a package of one binary needs).
#
#   usr/bin/ferrobus
#   usr/share/man/man1/ferrobus*.1.gz                     ferrobus man --dir, gzip -9n
#   usr/share/bash-completion/completions/ferrobus        ferrobus completions bash
#   usr/share/zsh/vendor-completions/_ferrobus            ferrobus completions zsh
#   usr/share/fish/vendor_completions.d/ferrobus.fish     ferrobus completions fish
#   usr/share/ferrobus/profiles/*.toml                    the built-in device profiles
#   usr/lib/systemd/system/ferrobus-{gateway,bridge}.service   scripts/systemd/
#   usr/share/doc/ferrobus/{copyright,README.md.gz}
#
# The man pages and completions are made by running the binary, so it must run here: for another
# architecture give --gen-bin, a binary of this machine's (release.sh does). The completions call
# `ferrobus` on PATH at each Tab.
#
#   scripts/deb.sh [--bin PATH] [--gen-bin PATH] [--arch amd64|arm64|...] [--out DIR] [--compress xz|gzip]
#
# The binary is stripped (strip, or aarch64-linux-gnu-strip for arm64). xz makes the smallest
# package; gzip is for the tests, seconds faster.
#
# Defaults: --bin target/release/ferrobus (built with cargo build --release --locked if missing),
# --gen-bin the --bin, --arch this machine's (dpkg --print-architecture), --out target/deb.
# Prints the path of the .deb on stdout.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bin=""
gen=""
arch=""
out="$root/target/deb"
compress=xz
while [ $# -gt 0 ]; do
    case "$1" in
    --bin) bin="$2"; shift 2 ;;
    --gen-bin) gen="$2"; shift 2 ;;
    --arch) arch="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --compress) compress="$2"; shift 2 ;;
    *) echo "deb.sh: unknown argument '$1' (see the top of $0)" >&2; exit 2 ;;
    esac
done
if [ -z "$bin" ]; then
    bin="$root/target/release/ferrobus"
    [ -x "$bin" ] || (cd "$root" && cargo build --release --locked -p ferrobus-cli --bin ferrobus >&2)
fi
[ -x "$bin" ] || { echo "deb.sh: no executable at $bin" >&2; exit 1; }
gen="${gen:-$bin}"
arch="${arch:-$(dpkg --print-architecture)}"
version="$(sed -n 's/^version = "\(.*\)"/\1/p' "$root/Cargo.toml" | head -1)"
[ -n "$version" ] || { echo "deb.sh: no version in $root/Cargo.toml [workspace.package]" >&2; exit 1; }

mkdir -p "$out"
stage="$(mktemp -d "$out/stage.XXXXXX")"
trap 'rm -rf "$stage"' EXIT
pkg="$stage/ferrobus"
install -D -m 0755 "$bin" "$pkg/usr/bin/ferrobus"
case "$arch" in
"$(dpkg --print-architecture)") strip_tool=strip ;;
arm64) strip_tool=aarch64-linux-gnu-strip ;;
*) strip_tool="" ;;
esac
if [ -n "$strip_tool" ] && command -v "$strip_tool" >/dev/null; then
    "$strip_tool" --strip-unneeded "$pkg/usr/bin/ferrobus"
else
    echo "deb.sh: no strip for $arch: the binary keeps its symbols" >&2
fi
# The generator must not read the user's settings file.
export XDG_CONFIG_HOME="$stage/no-config"
"$gen" man --dir "$pkg/usr/share/man/man1"
gzip -9n "$pkg"/usr/share/man/man1/*.1
comp="$pkg/usr/share"
mkdir -p "$comp/bash-completion/completions" "$comp/zsh/vendor-completions" "$comp/fish/vendor_completions.d"
"$gen" completions bash >"$comp/bash-completion/completions/ferrobus"
"$gen" completions zsh >"$comp/zsh/vendor-completions/_ferrobus"
"$gen" completions fish >"$comp/fish/vendor_completions.d/ferrobus.fish"
# The services a plant runs (Type=notify, with the watchdog): started by no one until enabled.
for unit in "$root"/scripts/systemd/*.service; do
    install -D -m 0644 "$unit" "$pkg/usr/lib/systemd/system/$(basename "$unit")"
done
mkdir -p "$pkg/usr/share/ferrobus/profiles"
# Wherever the crate that ships them keeps them (crates/*/profiles/).
find "$root/crates" -path '*/profiles/*.toml' -not -path '*/target/*' -exec install -m 0644 {} "$pkg/usr/share/ferrobus/profiles/" \;
ls "$pkg"/usr/share/ferrobus/profiles/*.toml >/dev/null 2>&1 || { echo "deb.sh: no profiles under crates/*/profiles" >&2; exit 1; }
doc="$pkg/usr/share/doc/ferrobus"
install -d "$doc"
gzip -9n <"$root/README.md" >"$doc/README.md.gz"
cat >"$doc/copyright" <<COPYRIGHT
Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/
Upstream-Name: ferrobus
Source: $(sed -n 's/^repository = "\(.*\)"/\1/p' "$root/Cargo.toml" | head -1)

Files: *
Copyright: the ferrobus authors
License: MIT or Apache-2.0
 On Debian systems the Apache License 2.0 is in /usr/share/common-licenses/Apache-2.0.
COPYRIGHT
size="$(du -sk "$pkg/usr" | cut -f1)"
# The newest glibc symbol version the binary needs (readelf reads any architecture's ELF).
glibc="$(readelf -W -V "$pkg/usr/bin/ferrobus" | grep -o 'GLIBC_[0-9][0-9.]*' | sed 's/GLIBC_//' | sort -uV | tail -1)"
depends="libc6${glibc:+ (>= $glibc)}"
# No one's mailbox: set DEB_MAINTAINER="Name <address>" for a published package.
maintainer="${DEB_MAINTAINER:-ferrobus developers <ferrobus@invalid>}"
mkdir -p "$pkg/DEBIAN"
cat >"$pkg/DEBIAN/control" <<CONTROL
Package: ferrobus
Version: $version
Architecture: $arch
Maintainer: $maintainer
Installed-Size: $size
Depends: $depends
Section: utils
Priority: optional
Homepage: $(sed -n 's/^repository = "\(.*\)"/\1/p' "$root/Cargo.toml" | head -1)
Description: Modbus toolkit for drives and field devices over RS-485 and TCP
 ferrobus reads, writes and diagnoses Modbus devices over serial lines (RTU,
 ASCII) and TCP, simulates drives, and benchmarks a bus. It ships man pages,
 shell completions (bash, zsh, fish) and the built-in device profiles.
CONTROL
deb="$out/ferrobus_${version}_${arch}.deb"
dpkg-deb --root-owner-group "-Z$compress" --build "$pkg" "$deb" >&2
echo "$deb"
