#!/usr/bin/env bash
# scripts/release.sh - the release binaries and packages, into dist/.
#
#   x86_64-unknown-linux-gnu    built here         dist/ferrobus-VERSION-x86_64-unknown-linux-gnu.tar.gz
#                                                  dist/ferrobus_VERSION_amd64.deb
#   aarch64-unknown-linux-gnu   cross-built (a Raspberry Pi 3/4/5 on a 64-bit OS); needs
#                               `rustup target add aarch64-unknown-linux-gnu` and
#                               `apt-get install gcc-aarch64-linux-gnu libc6-dev-arm64-cross`
#                               (with qemu-user, `qemu-aarch64 -L /usr/aarch64-linux-gnu` runs it)
#                                                  dist/ferrobus-VERSION-aarch64-unknown-linux-gnu.tar.gz
#                                                  dist/ferrobus_VERSION_arm64.deb
#   x86_64-pc-windows-gnu       cross-built with mingw-w64
#                                                  dist/ferrobus-VERSION-x86_64-pc-windows-gnu.zip (.tar.gz without zip)
#   x86_64-apple-darwin         checked only: this machine compiles for macOS but cannot link
#                               (no macOS SDK or linker here); build it on a Mac with
#                               `cargo install --path crates/ferrobus-cli`
#
# Each archive holds the binary, man/ (ferrobus.1 and a page per command), completions/ (bash,
# zsh, fish, powershell, elvish), profiles/ (the built-in device profiles) and README.md; the
# pages and scripts are made by the x86_64 Linux binary. dist/SHA256SUMS lists them all.
# Needs no libudev for any target: Linux lists ports from sysfs.
#
#   scripts/release.sh                                # all of the above
#   RELEASE_TARGETS="x86_64-unknown-linux-gnu" scripts/release.sh
#
# Honours CARGO_TARGET_DIR. Release builds take minutes each on a small machine.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
target_dir="${CARGO_TARGET_DIR:-$root/target}"
dist="$root/dist"
targets="${RELEASE_TARGETS:-x86_64-unknown-linux-gnu aarch64-unknown-linux-gnu x86_64-pc-windows-gnu x86_64-apple-darwin}"
version="$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -1)"
host=x86_64-unknown-linux-gnu
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER="${CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER:-aarch64-linux-gnu-gcc}"

step() { printf '\n=== %s\n' "$*"; }
build() { cargo build --release --locked -p ferrobus-cli --bin ferrobus --target "$1"; }

mkdir -p "$dist"
step "$host (also makes the man pages and completions for the others)"
build "$host"
gen="$target_dir/$host/release/ferrobus"
extras="$(mktemp -d)"
trap 'rm -rf "$extras"' EXIT
export XDG_CONFIG_HOME="$extras/no-config" # the generator reads no user settings
"$gen" man --dir "$extras/man"
mkdir -p "$extras/completions" "$extras/profiles"
"$gen" completions bash >"$extras/completions/ferrobus.bash"
"$gen" completions zsh >"$extras/completions/_ferrobus"
"$gen" completions fish >"$extras/completions/ferrobus.fish"
"$gen" completions powershell >"$extras/completions/_ferrobus.ps1"
"$gen" completions elvish >"$extras/completions/ferrobus.elv"
find crates -path '*/profiles/*.toml' -not -path '*/target/*' -exec cp {} "$extras/profiles/" \;

# archive TARGET BINARY: dist/ferrobus-VERSION-TARGET.(tar.gz|zip)
archive() {
    local name="ferrobus-$version-$1" stage
    stage="$(mktemp -d)"
    mkdir "$stage/$name"
    cp "$2" "$stage/$name/"
    cp -r "$extras/man" "$extras/completions" "$extras/profiles" README.md "$stage/$name/"
    if [[ "$1" == *windows* ]] && command -v zip >/dev/null; then
        (cd "$stage" && zip -qr "$dist/$name.zip" "$name")
        echo "dist/$name.zip"
    else
        tar -C "$stage" -czf "$dist/$name.tar.gz" "$name"
        echo "dist/$name.tar.gz"
    fi
    rm -rf "$stage"
}

for target in $targets; do
    case "$target" in
    x86_64-unknown-linux-gnu)
        archive "$target" "$gen"
        scripts/deb.sh --bin "$gen" --arch amd64 --out "$dist"
        ;;
    aarch64-unknown-linux-gnu)
        step "$target"
        command -v "$CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER" >/dev/null || {
            echo "release: no $CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER: apt-get install gcc-aarch64-linux-gnu libc6-dev-arm64-cross" >&2
            exit 1
        }
        build "$target"
        bin="$target_dir/$target/release/ferrobus"
        file "$bin" 2>/dev/null | grep -q 'ARM aarch64' || { echo "release: $bin is not an aarch64 binary" >&2; exit 1; }
        archive "$target" "$bin"
        scripts/deb.sh --bin "$bin" --gen-bin "$gen" --arch arm64 --out "$dist"
        ;;
    x86_64-pc-windows-gnu)
        step "$target"
        build "$target"
        archive "$target" "$target_dir/$target/release/ferrobus.exe"
        ;;
    x86_64-apple-darwin)
        step "$target: cargo check only (no macOS linker or SDK on this machine)"
        (source .ci/darwin-env.sh && cargo check --release --locked -p ferrobus-cli --bin ferrobus --target "$target")
        ;;
    *)
        echo "release: no recipe for $target" >&2
        exit 2
        ;;
    esac
done
(cd "$dist" && sha256sum ferrobus* >SHA256SUMS)
step "dist/"
ls -l "$dist"
