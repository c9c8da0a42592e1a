//! Independent jobs side by side: `workers` threads take the next job from a shared
//! counter until none is left. Used by the frequency sweep and by studies, whose cases
//! each run on one thread: a case of a few thousand particles scales better as one of
//! several independent jobs (no synchronisation at all) than split over threads
//! within a step (a fork-join per stage, parallel efficiency well below 1 at 5k
//! particles, docs/performance.md).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Runs `job(i, &items[i])` for every item on `workers` threads (at least 1, at most
/// one per item) and returns the results in item order.
pub fn run_parallel<T: Sync, R: Send>(
    items: &[T],
    workers: usize,
    job: impl Fn(usize, &T) -> R + Sync,
) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<R>>> = Mutex::new(items.iter().map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..workers.clamp(1, items.len().max(1)) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::SeqCst);
                let Some(item) = items.get(i) else { break };
                let r = job(i, item);
                results.lock().unwrap_or_else(|p| p.into_inner())[i] = Some(r);
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_else(|p| p.into_inner())
        .into_iter()
        .flatten()
        .collect()
}

/// Worker count for `jobs` independent single-threaded jobs: one per core, at most
/// one per job.
pub fn default_workers(jobs: usize) -> usize {
    std::thread::available_parallelism()
        .map_or(1, std::num::NonZeroUsize::get)
        .clamp(1, jobs.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_item_order_on_any_worker_count() {
        let items: Vec<u64> = (0..37).collect();
        for workers in [0, 1, 3, 100] {
            let out = run_parallel(&items, workers, |i, &x| (i as u64, x * x));
            assert_eq!(out.len(), items.len());
            assert!(out
                .iter()
                .enumerate()
                .all(|(i, &(j, sq))| i as u64 == j && sq == j * j));
        }
    }
}
