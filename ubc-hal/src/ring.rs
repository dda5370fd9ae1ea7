//! A single-producer single-consumer ring of `N` slots (a power of two) for an interrupt
//! handler and the program, like `heapless::spsc::Queue` but with the capacity known at
//! compile time in both halves.
//!
//! heapless 0.9's queue halves work on a view of the queue whose capacity is a run-time
//! value, so every enqueue and dequeue divides by it; on the soft core a division takes 34
//! cycles and the serial ports move every byte through two rings. Here the index arithmetic
//! is a mask. Indices run freely (wrapping); `tail - head` is the number of items, and all
//! `N` slots are usable.

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicUsize, Ordering};

/// The ring's storage; place it in a `static` and [`Ring::split`] it once.
pub struct Ring<T, const N: usize> {
    slots: UnsafeCell<[T; N]>,
    /// Next slot to read, advanced by the consumer only.
    head: AtomicUsize,
    /// Next slot to write, advanced by the producer only.
    tail: AtomicUsize,
}

// SAFETY: a slot is written only by the producer while it is outside `head..tail` (free) and
// read only by the consumer while it is inside (filled); the Release store of `tail` after a
// write and the Acquire load before a read (and the same for `head` the other way) order the
// slot accesses between the two contexts. `split` hands out exactly one producer and one
// consumer (it takes `&'static mut self`), so no two contexts share a role.
unsafe impl<T: Copy + Send, const N: usize> Sync for Ring<T, N> {}

impl<T: Copy, const N: usize> Ring<T, N> {
    const POWER_OF_TWO: () = assert!(N.is_power_of_two(), "ring size must be a power of two");

    /// An empty ring whose slots hold `fill` until written.
    pub const fn new(fill: T) -> Self {
        let () = Self::POWER_OF_TWO;
        Self {
            slots: UnsafeCell::new([fill; N]),
            head: AtomicUsize::new(0),
            tail: AtomicUsize::new(0),
        }
    }

    /// The producer and consumer halves.
    pub fn split(&'static mut self) -> (Producer<T, N>, Consumer<T, N>) {
        let ring: &'static Self = self;
        (Producer { ring }, Consumer { ring })
    }

    fn len(&self) -> usize {
        self.tail
            .load(Ordering::Acquire)
            .wrapping_sub(self.head.load(Ordering::Acquire))
    }

    /// The slot for index `i` (any index: it is masked).
    fn slot(&self, i: usize) -> *mut T {
        // The masked index lies inside the array, so the pointer stays in bounds.
        self.slots.get().cast::<T>().wrapping_add(i & (N - 1))
    }
}

/// The writing half (the interrupt handler of a receiver, the program for a transmitter).
pub struct Producer<T: 'static, const N: usize> {
    ring: &'static Ring<T, N>,
}

/// The reading half.
pub struct Consumer<T: 'static, const N: usize> {
    ring: &'static Ring<T, N>,
}

impl<T: Copy, const N: usize> Producer<T, N> {
    /// Appends `item`, or gives it back when the ring is full.
    pub fn enqueue(&mut self, item: T) -> Result<(), T> {
        let tail = self.ring.tail.load(Ordering::Relaxed);
        if tail.wrapping_sub(self.ring.head.load(Ordering::Acquire)) >= N {
            return Err(item);
        }
        // SAFETY: the slot at `tail` is free (fewer than N items), and only this producer
        // writes free slots; the consumer does not read it before `tail` moves past it below.
        unsafe { self.ring.slot(tail).write(item) };
        self.ring
            .tail
            .store(tail.wrapping_add(1), Ordering::Release);
        Ok(())
    }

    /// Free slots (the consumer may free more meanwhile, never fewer).
    pub fn room(&self) -> usize {
        N - self
            .ring
            .tail
            .load(Ordering::Relaxed)
            .wrapping_sub(self.ring.head.load(Ordering::Acquire))
    }

    /// Appends as many of `items` as fit, in order; returns how many. One pass with the
    /// indices read and written once.
    pub fn enqueue_slice(&mut self, items: &[T]) -> usize {
        let tail = self.ring.tail.load(Ordering::Relaxed);
        let room = N - tail.wrapping_sub(self.ring.head.load(Ordering::Acquire));
        let n = items.len().min(room);
        for (k, &item) in items.iter().take(n).enumerate() {
            // SAFETY: the `room` slots from `tail` are free and only this producer writes free
            // slots; the consumer does not read them before `tail` moves past them below.
            unsafe { self.ring.slot(tail.wrapping_add(k)).write(item) };
        }
        self.ring
            .tail
            .store(tail.wrapping_add(n), Ordering::Release);
        n
    }

    /// Whether there is room for one more item.
    pub fn ready(&self) -> bool {
        self.ring.len() < N
    }

    /// Items in the ring.
    pub fn len(&self) -> usize {
        self.ring.len()
    }

    /// Whether the ring is empty.
    pub fn is_empty(&self) -> bool {
        self.ring.len() == 0
    }

    /// Slots in the ring.
    pub const fn capacity(&self) -> usize {
        N
    }
}

impl<T: Copy, const N: usize> Consumer<T, N> {
    /// Takes the oldest item.
    pub fn dequeue(&mut self) -> Option<T> {
        let head = self.ring.head.load(Ordering::Relaxed);
        if self.ring.tail.load(Ordering::Acquire) == head {
            return None;
        }
        // SAFETY: the slot at `head` is filled (head != tail) and the producer does not write
        // it again before `head` moves past it below.
        let item = unsafe { self.ring.slot(head).read() };
        self.ring
            .head
            .store(head.wrapping_add(1), Ordering::Release);
        Some(item)
    }

    /// Moves items into `buf` until it is full, the ring is empty, or an item equal to
    /// `until` has been moved (`None`: no such item); returns how many, and whether the last
    /// one was `until`. One pass with the indices read and written once.
    pub fn dequeue_until(&mut self, buf: &mut [T], until: Option<T>) -> (usize, bool)
    where
        T: PartialEq,
    {
        let head = self.ring.head.load(Ordering::Relaxed);
        let avail = self.ring.tail.load(Ordering::Acquire).wrapping_sub(head);
        let mut n = 0;
        let mut found = false;
        for (k, slot) in buf.iter_mut().take(avail).enumerate() {
            // SAFETY: the `avail` slots from `head` are filled (read from `tail` above) and
            // the producer does not write them again before `head` moves past them below.
            let item = unsafe { self.ring.slot(head.wrapping_add(k)).read() };
            *slot = item;
            n = k + 1;
            if Some(item) == until {
                found = true;
                break;
            }
        }
        self.ring
            .head
            .store(head.wrapping_add(n), Ordering::Release);
        (n, found)
    }

    /// The oldest item, left in place.
    pub fn peek(&self) -> Option<T> {
        let head = self.ring.head.load(Ordering::Relaxed);
        if self.ring.tail.load(Ordering::Acquire) == head {
            return None;
        }
        // SAFETY: as in `dequeue`; the slot stays filled while this consumer does not move.
        Some(unsafe { self.ring.slot(head).read() })
    }

    /// Whether an item is waiting.
    pub fn ready(&self) -> bool {
        self.ring.len() != 0
    }

    /// Items waiting.
    pub fn len(&self) -> usize {
        self.ring.len()
    }

    /// Whether the ring is empty.
    pub fn is_empty(&self) -> bool {
        self.ring.len() == 0
    }

    /// Slots in the ring.
    pub const fn capacity(&self) -> usize {
        N
    }
}

impl<T, const N: usize> core::fmt::Debug for Ring<T, N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Ring")
            .field("head", &self.head.load(Ordering::Relaxed))
            .field("tail", &self.tail.load(Ordering::Relaxed))
            .finish_non_exhaustive()
    }
}

impl<T, const N: usize> core::fmt::Debug for Producer<T, N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Producer").finish_non_exhaustive()
    }
}

impl<T, const N: usize> core::fmt::Debug for Consumer<T, N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Consumer").finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::VecDeque;

    fn ring<const N: usize>() -> (Producer<u8, N>, Consumer<u8, N>) {
        Box::leak(Box::new(Ring::<u8, N>::new(0))).split()
    }

    #[test]
    fn every_slot_is_usable_and_full_gives_the_item_back() {
        let (mut p, mut c) = ring::<4>();
        for b in 1..=4 {
            assert_eq!(p.enqueue(b), Ok(()));
        }
        assert!(!p.ready());
        assert_eq!(p.enqueue(9), Err(9));
        assert_eq!(c.peek(), Some(1));
        assert_eq!(c.dequeue(), Some(1));
        assert_eq!(p.enqueue(5), Ok(()));
        let out: Vec<u8> = std::iter::from_fn(|| c.dequeue()).collect();
        assert_eq!(out, [2, 3, 4, 5]);
        assert!(c.is_empty());
    }

    #[test]
    fn indices_wrap_around_the_word() {
        let r = Box::leak(Box::new(Ring::<u8, 8>::new(0)));
        r.head.store(usize::MAX - 2, Ordering::Relaxed);
        r.tail.store(usize::MAX - 2, Ordering::Relaxed);
        let (mut p, mut c) = r.split();
        for b in 0..8 {
            assert_eq!(p.enqueue(b), Ok(()));
        }
        assert_eq!(p.len(), 8);
        for b in 0..8 {
            assert_eq!(c.dequeue(), Some(b));
        }
        assert_eq!(c.dequeue(), None);
    }

    #[test]
    fn threads_move_every_item_in_order() {
        let (mut p, mut c) = ring::<16>();
        let n = 200_000u32;
        let writer = std::thread::spawn(move || {
            let mut i = 0u32;
            while i < n {
                if p.enqueue(i as u8).is_ok() {
                    i += 1;
                }
            }
        });
        let mut next = 0u32;
        while next < n {
            if let Some(b) = c.dequeue() {
                assert_eq!(b, next as u8);
                next += 1;
            }
        }
        writer.join().unwrap();
    }

    #[test]
    fn enqueue_slice_takes_what_fits() {
        let (mut p, mut c) = ring::<4>();
        assert_eq!(p.room(), 4);
        assert_eq!(p.enqueue_slice(&[1, 2, 3]), 3);
        assert_eq!(p.room(), 1);
        assert_eq!(p.enqueue_slice(&[4, 5, 6]), 1);
        assert_eq!(p.enqueue_slice(&[7]), 0);
        let out: Vec<u8> = std::iter::from_fn(|| c.dequeue()).collect();
        assert_eq!(out, [1, 2, 3, 4]);
        assert_eq!(p.enqueue_slice(&[]), 0);
    }

    #[test]
    fn dequeue_until_stops_after_the_delimiter_or_when_full() {
        let (mut p, mut c) = ring::<8>();
        for b in [1, 2, 0, 3, 4] {
            p.enqueue(b).unwrap();
        }
        let mut buf = [9u8; 8];
        assert_eq!(c.dequeue_until(&mut buf, Some(0)), (3, true));
        assert_eq!(&buf[..3], [1, 2, 0]);
        let mut small = [0u8; 1];
        assert_eq!(c.dequeue_until(&mut small, Some(0)), (1, false));
        assert_eq!(c.dequeue_until(&mut buf, None), (1, false));
        assert_eq!(buf[0], 4);
        assert_eq!(c.dequeue_until(&mut buf, Some(0)), (0, false));
    }

    proptest! {
        /// `dequeue_until` takes what a loop of `dequeue` would, and stops at the same place.
        #[test]
        fn dequeue_until_matches_dequeue(items in prop::collection::vec(0u8..4, 0..40),
                                         cap in 0usize..12, until in prop::option::of(0u8..4)) {
            let (mut p1, mut c1) = ring::<64>();
            let (mut p2, mut c2) = ring::<64>();
            for &b in &items {
                p1.enqueue(b).unwrap();
                p2.enqueue(b).unwrap();
            }
            let mut buf = vec![0u8; cap];
            let (n, found) = c1.dequeue_until(&mut buf, until);
            let mut want = Vec::new();
            let mut want_found = false;
            while want.len() < cap {
                let Some(b) = c2.dequeue() else { break };
                want.push(b);
                if Some(b) == until {
                    want_found = true;
                    break;
                }
            }
            prop_assert_eq!(&buf[..n], &want[..]);
            prop_assert_eq!(found, want_found);
            prop_assert_eq!(c1.len(), c2.len());
        }

        /// Against a VecDeque bounded to the same size.
        #[test]
        fn behaves_like_a_bounded_deque(ops in prop::collection::vec(prop::option::of(any::<u8>()), 0..400)) {
            let (mut p, mut c) = ring::<32>();
            let mut model = VecDeque::new();
            for op in ops {
                match op {
                    Some(b) => {
                        let ok = model.len() < 32;
                        if ok {
                            model.push_back(b);
                        }
                        prop_assert_eq!(p.enqueue(b).is_ok(), ok);
                    }
                    None => prop_assert_eq!(c.dequeue(), model.pop_front()),
                }
                prop_assert_eq!(c.len(), model.len());
                prop_assert_eq!(c.peek(), model.front().copied());
            }
        }
    }
}
