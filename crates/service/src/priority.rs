//! Scheduling priority of the threads that do heavy work. Map builds (the global rayon pool and
//! the job threads that drive it) and heavy queries (the query pool) run at a lower priority
//! than the async runtime, so that on a machine whose cores they fill, a health check or a
//! cached query is scheduled the moment its packet arrives instead of waiting for a time slice.
//! Admission control bounds how much heavy work there is; this decides who runs first while it
//! runs.

/// Nice value of the worker threads. Under Linux's fair scheduler a nice-10 thread weighs 110
/// against a runtime thread's 1024, so a woken runtime thread preempts a worker at once and gets
/// about 90 % of a shared core; the workers still take every cycle the runtime leaves idle, so
/// builds are not slower on an otherwise quiet server. Higher values (up to 19) would change
/// little more: the runtime already wins every wakeup at 10.
pub(crate) const WORKER_NICE: i32 = 10;

/// Lowers the calling thread's priority to [`WORKER_NICE`] (never raises it: a server started
/// under `nice -n 15` keeps 15). On Linux the nice value is a per-thread attribute and
/// `setpriority(PRIO_PROCESS, 0, …)` addresses the calling thread alone. Elsewhere a no-op.
/// Failure is logged, not fatal: priority is an optimisation, not a guarantee.
pub(crate) fn lower_this_thread() {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: both calls take plain integers and touch no memory of ours.
        let current = unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) };
        if current >= WORKER_NICE {
            return;
        }
        if unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, WORKER_NICE) } != 0 {
            tracing::debug!(
                error = %std::io::Error::last_os_error(),
                "could not lower a worker thread's priority"
            );
        }
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    fn nice_of_this_thread() -> i32 {
        unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) }
    }

    #[test]
    fn only_the_calling_thread_is_lowered() {
        let before = nice_of_this_thread();
        let worker = std::thread::spawn(|| {
            lower_this_thread();
            nice_of_this_thread()
        })
        .join()
        .unwrap();
        assert_eq!(worker, WORKER_NICE.max(before));
        assert_eq!(
            nice_of_this_thread(),
            before,
            "the caller's own priority changed"
        );
    }

    #[test]
    fn a_thread_already_lower_keeps_its_priority() {
        let kept = std::thread::spawn(|| {
            unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, WORKER_NICE + 5) };
            lower_this_thread();
            nice_of_this_thread()
        })
        .join()
        .unwrap();
        // A test run under a higher nice than this cannot go back down to WORKER_NICE + 5.
        assert_eq!(kept, (WORKER_NICE + 5).max(nice_of_this_thread()));
    }
}
