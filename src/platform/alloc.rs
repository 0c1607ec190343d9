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
//! A one-shot command (`fit`: one fit per process) pays for its first touches
//! every run, which keeping freed blocks cannot help: `huge_heap_one_arena` makes
//! them cheap (see its doc).
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

/// Heap grown ahead of use and marked for transparent huge pages: the working set
/// of a 512² accurate fit or a 1280×960 fast one fits in it.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HUGE_HEAP_BYTES: usize = 128 << 20;
/// The block that makes the heap grow now (below the mmap threshold, so it is
/// served from the heap; above anything free at its top this early).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const GROW_BYTES: usize = 16 << 20;
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HUGE_PAGE_BYTES: usize = 2 << 20;

/// For one-shot commands (`fit`), after `keep_freed_blocks` and before any other
/// thread starts: a fresh process's fit faults in every page of its planes once (a 512²
/// accurate noise fit: ~6 100 faults of 4 KiB, a third of its time in the kernel's
/// fault path under `perf`). Here the heap is grown by 128 MiB at once (M_TOP_PAD)
/// and that range marked MADV_HUGEPAGE, so where the kernel's transparent huge
/// pages are `madvise` or `always` a first touch maps 2 MiB; and the process keeps
/// one malloc arena (M_ARENA_MAX = 1), so the fit pool's threads allocate from that
/// heap instead of arenas of their own. Measured on the side-by-side's six 512²
/// cases (`benches/official/side_by_side.py`'s inputs, `fit --threads 1`, fresh
/// processes, the builds with and without this interleaved): the three accurate
/// fits 39.0 → 27.8 ms, a noise fit's faults 6 140 → 1 060; the fast tier at
/// 1280×960 40.8 → 30.0 ms (BENCHMARKS.md). The cost: a first run after the kernel's huge pages
/// are used up may wait for compaction (seen: one run in fifteen 1.4× slower than
/// without), and threads share one arena's lock (a one-shot fit allocates plane
/// by plane, not per pixel). Not for the long-running app (`xr`, the worker): its
/// frame loop should not share a lock with the worker, and it is warm after its
/// first update.
pub fn huge_heap_one_arena() -> AllocTuning {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only reads its integer arguments (0 on refusal).
        if unsafe { libc::mallopt(libc::M_ARENA_MAX, 1) } == 0 {
            return AllocTuning::Refused("M_ARENA_MAX");
        }
        // SAFETY: as above.
        if unsafe { libc::mallopt(libc::M_TOP_PAD, HUGE_HEAP_BYTES as libc::c_int) } == 0 {
            return AllocTuning::Refused("M_TOP_PAD");
        }
        // SAFETY: a block is allocated and freed, never touched; sbrk(0) only reads
        // the break; madvise gets a range inside the heap's mapping (from the block,
        // rounded up to a huge page, to the break), which it only advises.
        unsafe {
            let base = libc::sbrk(0) as usize;
            let block = libc::malloc(GROW_BYTES);
            if block.is_null() {
                return AllocTuning::Refused("malloc");
            }
            let start = (block as usize).next_multiple_of(HUGE_PAGE_BYTES);
            let top = libc::sbrk(0) as usize;
            // Only where the block came from the break's heap (glibc may serve it
            // by mmap: a refused mmap threshold, a failed brk): the break moved and
            // the block ends between the old and the new break (it may start below
            // the old one, in the free space that was left at the heap's top), so
            // [block, top) is the heap's own mapping.
            let end = block as usize + GROW_BYTES;
            let from_heap = top > base && end > base && end <= top;
            if from_heap && top > start {
                // Refused where the kernel has no transparent huge pages: the heap
                // then stays in 4 KiB pages, as without this call.
                libc::madvise(start as *mut libc::c_void, top - start, libc::MADV_HUGEPAGE);
            }
            libc::free(block);
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
