//! How the process hands memory back. glibc's malloc serves a block of at least its mmap
//! threshold with a mapping of its own, returned to the system when freed; smaller blocks come
//! from per-thread arenas, whose freed memory mostly stays with the process. The threshold is
//! dynamic by default: each freed mapped block raises it to that block's size (up to 32 MB), so
//! after the first 16 MB map body is freed the next ones come from the arenas of the query
//! workers that wrote them, and the answers-in-flight budget (`--answers-in-flight-mb`) no
//! longer bounds what the process holds. With two query workers, 150 unread 16 MB map bodies
//! left it 139–143 MB larger, against 93–96 MB with the threshold fixed
//! (`tests/reliability/suite.py BINARY slow-readers`).

/// Blocks of this size or more are always mapped on their own and returned when freed. Path
/// answers (0.3 MB for 570 waypoints) stay below it; map bodies, exports and pictures of large
/// maps, whose memory the budget accounts for, go above. The cost is a mapping and its page
/// faults per large block: about a millisecond for 16 MB, beside tens of milliseconds to write it.
const MMAP_THRESHOLD_BYTES: i32 = 1 << 20;

/// Fixes glibc's mmap threshold at [`MMAP_THRESHOLD_BYTES`] for the whole process (a no-op
/// with another C library or system). Called once, before the server's threads start.
pub(crate) fn return_large_blocks() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt takes two integers and changes the allocator's settings only.
        if unsafe { libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) } != 1 {
            tracing::warn!("could not fix malloc's mmap threshold: freed answers may stay held");
        }
    }
}
