//! Running a closure as one of rayon's workers (tried for issue 37, not landed; see
//! README.md beside this file).
//!
//! Why: flex splits each large operation over rayon's global pool. Called from a thread
//! outside the pool (the CLI's main thread), the caller does the serial work between
//! operations while the pool's workers spin waiting for the next job: three busy threads
//! on two cores. Run inside the pool, the caller is a worker.

/// `f()` run on a worker of rayon's global pool (the caller blocks until it returns).
pub fn in_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| f())
}
