# Sourced before a `cargo check` or `cargo clippy` for x86_64-apple-darwin on this Linux machine,
# which has no macOS SDK: such a check compiles the C that crates build (criterion's one file,
# ring's crypto) and links nothing. clang compiles it freestanding; ring is told to use no libc
# headers (RING_CORE_NOSTDLIBINC) and gets a stand-in for the SDK's TargetConditionals.h.
ci_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
export CC_x86_64_apple_darwin=clang
export AR_x86_64_apple_darwin=llvm-ar
export CFLAGS_x86_64_apple_darwin="-ffreestanding -DRING_CORE_NOSTDLIBINC=1 -I$ci_dir/darwin-include"
unset ci_dir
