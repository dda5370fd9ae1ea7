//! A fixed gang of threads that steps every item of a list once per round: the calling
//! thread and `threads - 1` helpers each own a share of the list and take its items in turn,
//! then help with the others' shares (so a slow car does not hold up the ones behind it), and
//! the round ends when every item is done. A thread keeps to its share while it can because
//! a car's state (its SoC's RAM above all) then stays in that core's cache from one round to
//! the next; which thread steps a car never changes what the car does.
//!
//! The arena runs one round per quantum of world time, tens of thousands per second, each
//! only microseconds of work per car: a thread pool that puts its threads to sleep between
//! rounds (rayon's) spends more on waking them than on the cars. Here a thread waiting for
//! the next round first spins briefly, then yields, and only then sleeps on a condition
//! variable, so back-to-back rounds cost a few atomic operations. Each item sits behind its
//! own mutex, which only one thread takes at a time.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

/// Spins of a waiting thread before it yields its core.
const SPINS: u32 = 4_000;
/// Yields before it sleeps.
const YIELDS: u32 = 20;
/// Longest a sleeping thread waits before it looks again (a missed wake-up costs this).
const NAP: Duration = Duration::from_millis(2);

/// The work a round does on each item, with the round's argument.
type Work<T> = Box<dyn Fn(&mut T, u64) + Send + Sync>;

/// A value on a cache line of its own, so that the threads writing neighbouring counters do
/// not take the line from each other.
#[repr(align(128))]
struct Padded<V>(V);

/// What the gang's threads share.
struct Shared<T> {
    items: Vec<Mutex<T>>,
    work: Work<T>,
    /// Round number; a new value starts a round.
    round: AtomicU64,
    /// The argument of the current round.
    arg: AtomicU64,
    /// Per thread: the next item of its share to take.
    next: Vec<Padded<AtomicUsize>>,
    /// Per thread: its share, `start..end` of the items.
    shares: Vec<(usize, usize)>,
    /// Items finished in the current round (each thread adds what it did when it runs out).
    done: Padded<AtomicUsize>,
    stop: AtomicBool,
    sleep: Mutex<()>,
    wake: Condvar,
}

impl<T> Shared<T> {
    fn lock(&self, k: usize) -> Option<MutexGuard<'_, T>> {
        // A panic inside `work` poisons the mutex; the item is still usable for reports.
        self.items
            .get(k)
            .map(|m| m.lock().unwrap_or_else(PoisonError::into_inner))
    }

    /// Thread `me` takes items until none is left in this round: its own share first, then
    /// the others'.
    fn take_items(&self, me: usize) {
        let threads = self.next.len();
        let mut did = 0;
        for j in (0..threads).map(|i| (me + i) % threads) {
            let end = self.shares[j].1;
            loop {
                let k = self.next[j].0.fetch_add(1, Ordering::AcqRel);
                if k >= end {
                    break;
                }
                // Read after taking the index: a thread still finishing the last round may
                // take an item of the next one.
                let arg = self.arg.load(Ordering::Acquire);
                let Some(mut item) = self.lock(k) else {
                    break;
                };
                (self.work)(&mut item, arg);
                drop(item);
                did += 1;
            }
        }
        if did > 0 && self.done.0.fetch_add(did, Ordering::AcqRel) + did == self.items.len() {
            // The caller may be asleep waiting for the last item.
            let _g = self.sleep.lock().unwrap_or_else(PoisonError::into_inner);
            self.wake.notify_all();
        }
    }

    /// Waits until `ready()` holds: spins, yields, then sleeps.
    fn wait(&self, ready: impl Fn() -> bool) {
        for _ in 0..SPINS {
            if ready() {
                return;
            }
            std::hint::spin_loop();
        }
        for _ in 0..YIELDS {
            if ready() {
                return;
            }
            std::thread::yield_now();
        }
        let mut g = self.sleep.lock().unwrap_or_else(PoisonError::into_inner);
        while !ready() {
            g = self
                .wake
                .wait_timeout(g, NAP)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }
}

/// A gang of threads over a list of items.
pub struct Gang<T: Send + 'static> {
    shared: Arc<Shared<T>>,
    helpers: Vec<JoinHandle<()>>,
}

impl<T: Send + 'static> std::fmt::Debug for Gang<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gang")
            .field("items", &self.shared.items.len())
            .field("threads", &(self.helpers.len() + 1))
            .finish()
    }
}

impl<T: Send + 'static> Gang<T> {
    /// A gang of `threads` threads in all (the caller is one of them) that applies `work` to
    /// every item in each round.
    pub fn new(
        items: Vec<T>,
        threads: usize,
        name: &str,
        work: impl Fn(&mut T, u64) + Send + Sync + 'static,
    ) -> std::io::Result<Self> {
        let threads = threads.max(1);
        let n = items.len();
        let shares: Vec<(usize, usize)> = (0..threads)
            .map(|t| (t * n / threads, (t + 1) * n / threads))
            .collect();
        let shared = Arc::new(Shared {
            items: items.into_iter().map(Mutex::new).collect(),
            work: Box::new(work),
            round: AtomicU64::new(0),
            arg: AtomicU64::new(0),
            // Every share taken until the first round.
            next: shares
                .iter()
                .map(|&(_, end)| Padded(AtomicUsize::new(end)))
                .collect(),
            shares,
            done: Padded(AtomicUsize::new(0)),
            stop: AtomicBool::new(false),
            sleep: Mutex::new(()),
            wake: Condvar::new(),
        });
        let mut gang = Gang {
            shared,
            helpers: Vec::new(),
        };
        for i in 1..threads {
            let s = Arc::clone(&gang.shared);
            let h = std::thread::Builder::new()
                .name(format!("{name}-{i}"))
                .spawn(move || helper(&s, i))?;
            gang.helpers.push(h);
        }
        Ok(gang)
    }

    /// Threads in the gang, the caller included.
    pub fn threads(&self) -> usize {
        self.helpers.len() + 1
    }

    /// Items in the list.
    pub fn len(&self) -> usize {
        self.shared.items.len()
    }

    /// Whether the list is empty.
    pub fn is_empty(&self) -> bool {
        self.shared.items.is_empty()
    }

    /// Item `k`, for the caller alone between rounds.
    pub fn item(&self, k: usize) -> Option<MutexGuard<'_, T>> {
        self.shared.lock(k)
    }

    /// One round: `work(item, arg)` for every item, spread over the gang; returns when all
    /// are done.
    pub fn round(&self, arg: u64) {
        let s = &self.shared;
        s.arg.store(arg, Ordering::Release);
        s.done.0.store(0, Ordering::Release);
        for (next, &(start, _)) in s.next.iter().zip(&s.shares) {
            next.0.store(start, Ordering::Release);
        }
        s.round.fetch_add(1, Ordering::AcqRel);
        if !self.helpers.is_empty() {
            let _g = s.sleep.lock().unwrap_or_else(PoisonError::into_inner);
            s.wake.notify_all();
        }
        s.take_items(0);
        s.wait(|| s.done.0.load(Ordering::Acquire) >= s.items.len());
    }
}

fn helper<T>(s: &Shared<T>, me: usize) {
    let mut seen = 0;
    loop {
        s.wait(|| s.stop.load(Ordering::Acquire) || s.round.load(Ordering::Acquire) != seen);
        if s.stop.load(Ordering::Acquire) {
            return;
        }
        seen = s.round.load(Ordering::Acquire);
        s.take_items(me);
    }
}

impl<T: Send + 'static> Drop for Gang<T> {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        {
            let _g = self
                .shared
                .sleep
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            self.shared.wake.notify_all();
        }
        for h in self.helpers.drain(..) {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_once_per_round_on_any_number_of_threads() {
        for threads in [1, 2, 3, 8] {
            let gang = Gang::new(vec![0u64; 37], threads, "t", |x, arg| *x += arg).unwrap();
            assert_eq!(gang.threads(), threads);
            for r in 1..=500u64 {
                gang.round(r);
            }
            for k in 0..gang.len() {
                assert_eq!(*gang.item(k).unwrap(), 500 * 501 / 2, "threads {threads}");
            }
        }
    }

    #[test]
    fn rounds_after_a_pause_still_run() {
        let gang = Gang::new(vec![0u32; 4], 2, "t", |x, _| *x += 1).unwrap();
        gang.round(0);
        // Long enough for the helper to fall asleep.
        std::thread::sleep(Duration::from_millis(50));
        gang.round(0);
        assert!((0..4).all(|k| *gang.item(k).unwrap() == 2));
    }

    #[test]
    fn empty_gang_and_dropping_while_idle() {
        let gang = Gang::new(Vec::<u8>::new(), 3, "t", |_, _| {}).unwrap();
        assert!(gang.is_empty());
        gang.round(1);
        drop(gang);
    }
}
