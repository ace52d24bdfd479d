//! The one counting allocator of the allocation tests: a global allocator that forwards to the system's and counts
//! every allocation (`alloc`, `alloc_zeroed`, `realloc`; not `dealloc`), on the calling thread and in all.
//!
//! A test file installs it itself (a `#[global_allocator]` in this library would swap the allocator of every test
//! binary that uses the kit), then compares counts around the code under test:
//!
//! ```
//! use roitrack_testkit::alloc::{CountingAllocator, allocations_on_this_thread};
//!
//! #[global_allocator]
//! static GLOBAL: CountingAllocator = CountingAllocator;
//!
//! let before = allocations_on_this_thread();
//! let heap = vec![0u8; 100];
//! assert_eq!(allocations_on_this_thread(), before + 1);
//! # drop(heap);
//! ```
//!
//! Count on this thread ([`allocations_on_this_thread`]) when the code under test runs on it, so that the test
//! harness's other threads do not count; count in all ([`allocations_in_all_threads`]) when it runs threads of its
//! own (the real-time loop), with nothing else running.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, counting. Install it with `#[global_allocator]` in the test file.
pub struct CountingAllocator;

static ALL_THREADS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Allocations made by this thread (const-initialised: counting never allocates).
    static THIS_THREAD: Cell<usize> = const { Cell::new(0) };
}

fn count() {
    ALL_THREADS.fetch_add(1, Ordering::SeqCst);
    // `try_with`: the thread's counter may be gone while the thread exits.
    let _ = THIS_THREAD.try_with(|n| n.set(n.get() + 1));
}

/// The allocations made so far by the calling thread (through [`CountingAllocator`], once installed).
pub fn allocations_on_this_thread() -> usize {
    THIS_THREAD.with(Cell::get)
}

/// The allocations made so far by every thread of the process (through [`CountingAllocator`], once installed).
pub fn allocations_in_all_threads() -> usize {
    ALL_THREADS.load(Ordering::SeqCst)
}

// SAFETY: every method forwards to `System` with the caller's arguments unchanged, so it keeps `System`'s guarantees;
// counting touches only an atomic and a const-initialised thread-local `Cell`, which never allocate.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: the caller's contract for `alloc` is `System.alloc`'s.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: the caller's contract for `alloc_zeroed` is `System.alloc_zeroed`'s.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated by `System` (every allocation above is), with this `layout`.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: `ptr` was allocated by `System` with `layout`; the rest of the contract is `System.realloc`'s.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
