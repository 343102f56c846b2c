//! Independent jobs run side by side on the machine's cores.

use std::sync::atomic::{AtomicUsize, Ordering};

/// Runs `f` on every job, on as many threads as the machine has cores (at most one per job),
/// each thread taking the next job when it finishes one; returns the results in the jobs'
/// order. Jobs of unequal length keep every thread busy, and deterministic jobs give results
/// that do not depend on the thread count. A panic in a job is a bug: it propagates, as it
/// would without the threads.
pub(crate) fn side_by_side<J: Sync, R: Send>(jobs: &[J], f: impl Fn(&J) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(jobs.len());
    if threads < 2 {
        return jobs.iter().map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let mut done: Vec<(usize, R)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some(job) = jobs.get(i) else { break };
                        done.push((i, f(job)));
                    }
                    done
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every job runs once and the results come back in the jobs' order, whatever order the
    /// threads finish them in.
    #[test]
    fn results_come_back_in_the_jobs_order() {
        let jobs: Vec<u64> = (0..23).collect();
        let runs = AtomicUsize::new(0);
        let out = side_by_side(&jobs, |&j| {
            runs.fetch_add(1, Ordering::Relaxed);
            // Early jobs take longest, so later ones finish first.
            std::thread::sleep(std::time::Duration::from_millis(23 - j));
            j * j
        });
        assert_eq!(out, jobs.iter().map(|j| j * j).collect::<Vec<_>>());
        assert_eq!(runs.load(Ordering::Relaxed), jobs.len());
        assert!(side_by_side(&[] as &[u64], |&j| j).is_empty());
    }
}
