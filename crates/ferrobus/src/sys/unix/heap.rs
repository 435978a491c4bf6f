//! Linux with glibc: giving the allocator's free pages back to the OS.
//!
//! glibc keeps the pages of small allocations once they are freed (it returns only a free top
//! of the heap, and one long-lived allocation pins that), so the memory of a thousand closed
//! connections stays in the process for good unless it is asked for it (`malloc_trim`).

/// Returns the heap's free pages to the OS.
#[expect(unsafe_code, reason = "glibc's malloc_trim has no safe binding in std or rustix")]
pub(crate) fn release_free_memory() {
    unsafe extern "C" {
        /// glibc: releases free memory at the top of the heap and, since 2.8, the free whole
        /// pages inside it; `pad` bytes are kept at the top. Returns 1 if memory was released.
        fn malloc_trim(pad: usize) -> std::ffi::c_int;
    }
    // SAFETY: malloc_trim takes a plain integer and touches only the allocator's own state,
    // under the allocator's lock; it is safe to call at any time from any thread.
    unsafe {
        malloc_trim(0);
    }
}
