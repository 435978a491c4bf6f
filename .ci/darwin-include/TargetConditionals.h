/* A stand-in for the macOS SDK's TargetConditionals.h, which this machine does not have.
 * The macOS clippy check (scripts/test.sh, "lint: macOS") compiles ring's C and assembly for
 * x86_64-apple-darwin and links nothing; ring only asks which Apple OS it is built for. */
#ifndef FERROBUS_CI_TARGET_CONDITIONALS_H
#define FERROBUS_CI_TARGET_CONDITIONALS_H
#define TARGET_OS_MAC 1
#define TARGET_OS_OSX 1
#define TARGET_OS_IPHONE 0
#define TARGET_OS_IOS 0
#define TARGET_OS_TV 0
#define TARGET_OS_WATCH 0
#endif
