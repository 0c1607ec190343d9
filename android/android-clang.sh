#!/bin/sh
# Linker for aarch64-linux-android without the NDK: Debian's clang-16 + lld against
# the stub sysroot `cargo xtask apk` generates (ANDROID_STUB_SYSROOT). The name must
# not end in "ld": rustc infers the linker flavour from it. 16 KiB page alignment
# (Android 15+ devices), every symbol resolved at link time (--no-undefined: a symbol
# missing from android/sysroot/symbols.txt is a link error, not a crash on device).
SYSROOT=${ANDROID_STUB_SYSROOT:?set ANDROID_STUB_SYSROOT (cargo xtask apk does)}
exec clang-16 --target=aarch64-linux-android29 -fuse-ld=lld --sysroot="$SYSROOT" \
  -Wl,-z,max-page-size=16384 -Wl,--no-undefined -Wl,--build-id=sha1 "$@"
