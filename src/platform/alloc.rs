//! Process-wide allocator setup the app's binaries (and the benchmarks) run first:
//! the C allocator keeps freed frame-sized blocks instead of handing them back to
//! the kernel.
//!
//! Why: every fit allocates and frees planes of a frame's size (4.9 MB each at
//! 1280×960 f32), tens per call. glibc serves blocks above its mmap threshold
//! (128 KiB at start, raised dynamically up to 32 MiB) with `mmap` and returns the
//! heap's top to the kernel when more than the trim threshold (twice the mmap
//! threshold) lies free: every call then pays a page fault and a page clear per
//! 4 KiB on first touch, and an `munmap` (a TLB shootdown on every core the process
//! runs on — the render thread's included) per block. Measured (`perf`, the fast
//! tier at 1280×960 on one thread): 20–26% of its samples in the kernel's fault
//! path; the same frames with the thresholds below 67–71 ms instead of 82–85
//! (BENCHMARKS.md). The cost is memory: the heap keeps what a fit freed, up to its
//! peak, which the worker reaches again on its next update (a process fitting
//! those frames: maximum resident set 85 MB with the thresholds, 79 MB without).
//!
//! Android (bionic's scudo) has its own knobs (the secondary cache's size) and is
//! left at its defaults: not measured here, no headset.
#![allow(unsafe_code)]

/// Largest block glibc takes from the heap instead of `mmap`: glibc's own ceiling
/// for this setting (`HEAP_MAX_SIZE / 2` on 64-bit); a 1280×960 plane is 4.9 MB and
/// a 4-channel 2048² one 64 MB (still mmapped, rare).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD_BYTES: libc::c_int = 32 << 20;
/// Free memory at the heap's top glibc keeps before trimming: above a fit's peak.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const TRIM_THRESHOLD_BYTES: libc::c_int = 512 << 20;

/// What `keep_freed_blocks` did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AllocTuning {
    /// Both thresholds set (glibc).
    Applied,
    /// The allocator refused a setting (the named `mallopt` parameter).
    Refused(&'static str),
    /// No tuning for this platform's allocator (see the module docs).
    NotApplicable,
}

/// Tell the process's allocator to keep freed large blocks (see the module docs).
/// Call once, first thing in `main`; later calls are harmless.
pub fn keep_freed_blocks() -> AllocTuning {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        for (param, value, name) in [
            (libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES, "M_MMAP_THRESHOLD"),
            (libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES, "M_TRIM_THRESHOLD"),
        ] {
            // SAFETY: mallopt only reads its two integer arguments and updates the
            // allocator's parameters under its own lock; it returns 0 on refusal.
            if unsafe { libc::mallopt(param, value) } == 0 {
                return AllocTuning::Refused(name);
            }
        }
        AllocTuning::Applied
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        AllocTuning::NotApplicable
    }
}

#[cfg(all(test, target_os = "linux", target_env = "gnu"))]
mod tests {
    use super::*;

    /// Minor page faults of this thread so far.
    fn minor_faults() -> i64 {
        let mut u = std::mem::MaybeUninit::<libc::rusage>::zeroed();
        // SAFETY: `u` is a valid rusage to write; RUSAGE_THREAD is Linux's.
        let rc = unsafe { libc::getrusage(libc::RUSAGE_THREAD, u.as_mut_ptr()) };
        assert_eq!(rc, 0, "getrusage");
        // SAFETY: getrusage succeeded and wrote the whole struct (it was zeroed).
        unsafe { u.assume_init() }.ru_minflt
    }

    /// The point of the tuning, checked on the kernel's own count: freed
    /// frame-sized blocks come back without page faults. A fit holds several planes
    /// at once: four 1280×960 f32 blocks (4 × 1200 pages) allocated, touched and
    /// freed, three times after a first round that grows the heap. Without the
    /// tuning every round faults all 4800 pages (checked: glibc's dynamic threshold
    /// serves them from the heap, then trims the 20 MB they leave free, above its
    /// 2 × 4.9 MB trim threshold); with it a round may fault a few pages of
    /// allocator bookkeeping, not a block's worth (bound: 120, a tenth of one).
    #[test]
    fn freed_frame_sized_blocks_come_back_without_page_faults() {
        assert_eq!(keep_freed_blocks(), AllocTuning::Applied);
        let round = || {
            let before = minor_faults();
            let v: Vec<Vec<f32>> = (0..4).map(|k| vec![k as f32 + 1.0; 1280 * 960]).collect();
            std::hint::black_box(&v);
            drop(v);
            minor_faults() - before
        };
        round();
        let again: Vec<i64> = (0..3).map(|_| round()).collect();
        assert!(again.iter().all(|&f| f < 120), "page faults per round of four 4.9 MB blocks: {again:?}");
    }
}
