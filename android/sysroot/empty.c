/* Empty object: archived as the empty libunwind.a clang links for Android (unwinding comes from the `unwinding` crate). */
