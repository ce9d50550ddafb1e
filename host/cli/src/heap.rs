//! How the process's heap gives memory back to the kernel.
//!
//! Training on burn's autodiff graph (the NPE's) allocates and frees tensors of a few hundred
//! kilobytes to tens of megabytes at every step.
//! glibc's defaults hand the freed top of the heap back to the kernel as soon as it exceeds a
//! threshold that adapts to the largest recent free, and allocations above another one come
//! from `mmap` and go back on free: every step then faults its pages in again, zeroed by the
//! kernel. Measured on one epoch of `ocm npe train --symmetries rot180` on data set v3 (998
//! samples and their images): 15.0 million page faults and 33.7 s of system time beside 60 s of
//! user time; with the heap kept, 0.73 million faults and 2.0 s, the same losses. The tactile
//! networks' own training passes reuse their buffers and gain nothing (1.6 s of system time in
//! a 29 s epoch either way).

/// Freed memory at the top of the heap that glibc keeps instead of returning it, bytes.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const TRIM_THRESHOLD_BYTES: libc::c_int = 1 << 30;

/// Allocations from this size on are mapped on their own, bytes (glibc's largest allowed value
/// on 64-bit targets; setting it also stops the threshold adapting).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD_BYTES: libc::c_int = 32 << 20;

/// Keeps freed memory in the process for reuse (glibc); a no-op with other C libraries.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[allow(unsafe_code)]
    // SAFETY: mallopt only sets two of glibc's allocator parameters; it is called first thing in
    // main, before any other thread exists, and the values are within glibc's documented ranges
    // (a rejected value returns 0 and leaves the default, which is only slower).
    unsafe {
        libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES);
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES);
    }
}
