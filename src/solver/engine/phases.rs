//! A whole iteration in one parallel region: phases of vertex chunks that
//! the threads claim in order, instead of one task-pool scope per pass.
//!
//! A scope per pass parks and wakes the pool's threads twice per
//! iteration: on the perf page's 2-core machine the 256² Chebyshev step
//! made about 140 context switches and kept 1.5 of its 2 cores busy. Here
//! the participants claim work items `(phase, chunk)` from one counter, in
//! order, and before running an item wait (spinning, then yielding) until
//! every item of the earlier phases is done. An item is only ever claimed
//! by a running participant, so the wait always ends: with one participant
//! (the pool busy elsewhere) it runs every item itself, in order.
//!
//! Each item writes what only it writes (its chunk), and sums are kept per
//! chunk and added in chunk order, so the result does not depend on which
//! thread ran what: the same bits on any thread count.

use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};

use bevy::tasks::ComputeTaskPool;

/// Runs `item(phase, chunk, value)` for every chunk of every phase, phase
/// after phase: `value` is what `start(phase)` returned, called once per
/// phase, before the phase's items and after every item of the phase
/// before. On `pool`, with as many participants as it has threads (the
/// calling thread one of them); without, in order on the calling thread.
///
/// A panic in `item` or `start` stops the other participants and is
/// resumed on the calling thread.
pub(crate) fn run_phases(
    pool: Option<&ComputeTaskPool>,
    phases: usize,
    chunks: usize,
    mut start: impl FnMut(usize) -> u64 + Send,
    item: impl Fn(usize, usize, u64) + Sync,
) {
    let Some(pool) = pool.filter(|_| chunks > 1) else {
        for phase in 0..phases {
            let value = start(phase);
            for chunk in 0..chunks {
                item(phase, chunk, value);
            }
        }
        return;
    };
    let shared = Shared {
        total: phases * chunks,
        chunks,
        next: AtomicUsize::new(0),
        done: AtomicUsize::new(0),
        started: AtomicUsize::new(0),
        value: AtomicU64::new(0),
        failed: AtomicBool::new(false),
        panic: Mutex::new(None),
        start: Mutex::new(&mut start),
    };
    let participate = || shared.participate(&item);
    pool.scope(|scope| {
        for _ in 1..pool.thread_num() {
            scope.spawn(async { participate() });
        }
        participate();
    });
    let payload = shared.panic.lock().map_or(None, |mut p| p.take());
    if let Some(payload) = payload {
        resume_unwind(payload);
    }
}

type Panic = Box<dyn std::any::Any + Send>;

/// What the participants share.
struct Shared<'a, S> {
    total: usize,
    chunks: usize,
    /// The next item to claim.
    next: AtomicUsize,
    /// Items finished.
    done: AtomicUsize,
    /// Phases whose `start` has run.
    started: AtomicUsize,
    /// The current phase's `start` value.
    value: AtomicU64,
    /// Set when an item or `start` panicked: the others stop waiting.
    failed: AtomicBool,
    panic: Mutex<Option<Panic>>,
    start: Mutex<&'a mut S>,
}

impl<S: FnMut(usize) -> u64 + Send> Shared<'_, S> {
    fn participate(&self, item: &(impl Fn(usize, usize, u64) + Sync)) {
        loop {
            let id = self.next.fetch_add(1, Ordering::Relaxed);
            if id >= self.total {
                return;
            }
            let (phase, chunk) = (id / self.chunks, id % self.chunks);
            if !self.wait(|| self.done.load(Ordering::Acquire) >= phase * self.chunks) {
                return;
            }
            let run = catch_unwind(AssertUnwindSafe(|| {
                if chunk == 0 {
                    // Every item before this phase is done and none of it
                    // has started: `start` runs alone.
                    let mut start = self.start.lock().unwrap_or_else(|e| e.into_inner());
                    self.value.store(start(phase), Ordering::Relaxed);
                    self.started.store(phase + 1, Ordering::Release);
                } else if !self.wait(|| self.started.load(Ordering::Acquire) > phase) {
                    return;
                }
                item(phase, chunk, self.value.load(Ordering::Relaxed));
            }));
            if let Err(payload) = run {
                if let Ok(mut slot) = self.panic.lock() {
                    slot.get_or_insert(payload);
                }
                self.failed.store(true, Ordering::Release);
                return;
            }
            if self.failed.load(Ordering::Acquire) {
                return;
            }
            self.done.fetch_add(1, Ordering::AcqRel);
        }
    }

    /// Spins, then yields, until `ready`; false if a participant failed.
    fn wait(&self, ready: impl Fn() -> bool) -> bool {
        let mut spins = 0u32;
        while !ready() {
            if self.failed.load(Ordering::Acquire) {
                return false;
            }
            if spins < 256 {
                std::hint::spin_loop();
                spins += 1;
            } else {
                std::thread::yield_now();
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy::tasks::TaskPoolBuilder;
    use std::sync::atomic::AtomicU32;

    fn pool() -> &'static ComputeTaskPool {
        ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build())
    }

    /// Every item runs once, after every item of the phase before, with its
    /// phase's `start` value; serial and pooled alike.
    #[test]
    fn phases_run_in_order_with_their_start_values() {
        for pool in [None, Some(pool())] {
            let (phases, chunks) = (40, 7);
            let finished: Vec<AtomicU32> = (0..phases).map(|_| AtomicU32::new(0)).collect();
            let mut calls = Vec::new();
            run_phases(
                pool,
                phases,
                chunks,
                |p| {
                    if p > 0 {
                        assert_eq!(finished[p - 1].load(Ordering::SeqCst), chunks as u32);
                    }
                    calls.push(p);
                    (p as u64) * 1000
                },
                |p, _, value| {
                    assert_eq!(value, p as u64 * 1000);
                    if p > 0 {
                        assert_eq!(finished[p - 1].load(Ordering::SeqCst), chunks as u32);
                    }
                    finished[p].fetch_add(1, Ordering::SeqCst);
                },
            );
            assert_eq!(calls, (0..phases).collect::<Vec<_>>());
            assert!(
                finished
                    .iter()
                    .all(|f| f.load(Ordering::SeqCst) == chunks as u32)
            );
        }
    }

    /// A panicking item neither hangs the others nor is lost.
    #[test]
    fn a_panic_in_an_item_reaches_the_caller() {
        let caught = catch_unwind(|| {
            run_phases(
                Some(pool()),
                10,
                4,
                |_| 0,
                |p, c, _| {
                    assert!(!(p == 5 && c == 2), "item 5/2");
                },
            );
        });
        assert!(caught.is_err());
    }
}
