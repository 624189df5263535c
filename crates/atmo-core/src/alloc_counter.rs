//! A counting global allocator for the "allocates nothing after start-up"
//! tests of every crate (one copy, not one per test file).
//!
//! Each thread counts its own allocations (`alloc` and `realloc`, not
//! `dealloc`), so tests running in parallel in one binary never see each
//! other's. A test binary installs it with
//!
//! ```
//! #[global_allocator]
//! static GLOBAL: atmo_core::alloc_counter::CountingAllocator =
//!     atmo_core::alloc_counter::CountingAllocator;
//! # fn main() {
//! # let (_, n) = atmo_core::alloc_counter::count(|| vec![0u8; 16]);
//! # assert_eq!(n, 1);
//! # }
//! ```
//!
//! and measures with [`count`] (allocations of one call on this thread) or
//! [`thread_allocations`] (this thread's running total). Nothing is counted
//! in a binary that does not install it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

/// Forwards to the system allocator; counts per thread.
#[derive(Debug, Clone, Copy, Default)]
pub struct CountingAllocator;

fn bump() {
    // `try_with`: a thread's destructors may allocate after its TLS is gone.
    let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
}

// A global allocator is unsafe by definition; this one only counts and
// forwards to `System` with the caller's arguments unchanged.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        bump();
        // SAFETY: the caller's contract, passed on unchanged.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract, passed on unchanged.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        bump();
        // SAFETY: the caller's contract, passed on unchanged.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Allocations made on this thread so far (0 forever unless
/// [`CountingAllocator`] is the global allocator).
pub fn thread_allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

/// `f()` and the number of allocations it made on this thread.
pub fn count<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let before = thread_allocations();
    let out = f();
    (out, thread_allocations() - before)
}
