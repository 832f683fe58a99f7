//! A*'s open list: buckets of f = g + h, each a stack, in a ring that covers the few cells of f
//! a search can push ahead of what it pops.
//!
//! Pushes and pops are O(1): a cell goes on its bucket's stack and comes off the lowest
//! non-empty one. Within a bucket the order is last in, first out, not by f, so the search
//! that uses this queue must accept a cell being expanded before its shortest way is known and
//! expand it again when that way turns up (`CellGraph::a_star` does: it reopens improved
//! cells, and once the goal is settled it finishes the goal's bucket before it stops). That
//! search still returns the shortest path: every cell of a shortest path to the goal has f at
//! most the goal's length, so it lies in the goal's bucket or an earlier one, all of which are
//! emptied.
//!
//! Why a ring suffices: a step of length ℓ (1 or √2 cells) raises g by ℓ and changes the
//! octile heuristic by at most ℓ, so a pushed key is at most 2√2 cells above the key of the
//! cell being expanded, which lies in the current bucket. The ring covers [`WINDOW_CELLS`];
//! keys beyond it (none under a consistent heuristic) wait in an overflow list, and keys a
//! rounding error below the current bucket join it.

/// Buckets per cell of f. Narrower buckets mean fewer cells expanded before their shortest
/// way is known (those whose better way comes from the same bucket) but more empty buckets
/// to step over. On the 19-wall maze of `scripts/vs-python.sh` (f runs over 16 000 cells,
/// 800 000 cells settled) 8, 16, 32 and 64 to a cell measured within noise of each other
/// (medians 65–76 ms); 16 keeps the ring at 64 stacks.
const BUCKETS_PER_CELL: f64 = 16.0;

/// The ring's length in buckets, a power of two.
const RING: usize = 64;

/// The span of f the ring covers above its current bucket; must exceed 2√2 cells (the most a
/// push can be ahead of the current bucket) with room for rounding.
const WINDOW_CELLS: f64 = RING as f64 / BUCKETS_PER_CELL;
const _: () = assert!(WINDOW_CELLS > 2.0 * std::f64::consts::SQRT_2 + 0.5);

/// The open list; kept between searches (in the planner's scratch) with its stacks' capacity.
#[derive(Debug)]
pub(crate) struct BucketQueue {
    /// Bucket b's stack at `ring[b % RING]`; the current bucket's is the one popped.
    ring: Vec<Vec<u32>>,
    /// Absolute number of the current bucket.
    base: u64,
    /// Entries in `ring`.
    in_ring: usize,
    /// (bucket, cell) of entries more than the ring above `base`, and their least bucket
    /// (`u64::MAX` when none).
    overflow: Vec<(u64, u32)>,
    overflow_min: u64,
}

impl Default for BucketQueue {
    fn default() -> Self {
        BucketQueue {
            ring: (0..RING).map(|_| Vec::new()).collect(),
            base: 0,
            in_ring: 0,
            overflow: Vec::new(),
            overflow_min: u64::MAX,
        }
    }
}

/// The bucket of f (finite, ≥ 0).
#[inline]
fn bucket_of(f: f64) -> u64 {
    (f * BUCKETS_PER_CELL) as u64
}

impl BucketQueue {
    /// Empties the queue for a new search whose first key is `f`.
    pub fn reset(&mut self, f: f64) {
        for stack in &mut self.ring {
            stack.clear();
        }
        self.in_ring = 0;
        self.overflow.clear();
        self.overflow_min = u64::MAX;
        self.base = bucket_of(f);
    }

    /// The bucket being popped: a search compares it with the goal's to know when it is done.
    #[inline]
    pub fn bucket(&self) -> u64 {
        self.base
    }

    /// Queues `cell` at f (finite, ≥ 0); a key below the current bucket joins it.
    #[inline]
    pub fn push(&mut self, f: f64, cell: u32) {
        self.place(bucket_of(f).max(self.base), cell);
    }

    /// A cell of the lowest non-empty bucket (the last pushed there), or `None` when empty.
    #[inline]
    pub fn pop(&mut self) -> Option<u32> {
        loop {
            if let Some(cell) = self.ring[self.base as usize % RING].pop() {
                self.in_ring -= 1;
                return Some(cell);
            }
            self.advance()?;
        }
    }

    /// Moves `base` to the next bucket that holds entries; `None` when none is left.
    fn advance(&mut self) -> Option<()> {
        if self.in_ring == 0 {
            if self.overflow.is_empty() {
                return None;
            }
            // Only far entries are left: jump to the nearest.
            self.base = self.overflow_min;
            self.refill();
            return Some(());
        }
        loop {
            self.base += 1;
            if self.overflow_min < self.base + RING as u64 {
                self.refill();
            }
            if !self.ring[self.base as usize % RING].is_empty() {
                return Some(());
            }
        }
    }

    /// Moves the overflow entries the ring now covers into it.
    #[cold]
    fn refill(&mut self) {
        let mut pending = std::mem::take(&mut self.overflow);
        self.overflow_min = u64::MAX;
        for (bucket, cell) in pending.drain(..) {
            self.place(bucket, cell);
        }
        if self.overflow.is_empty() {
            self.overflow = pending; // its capacity, for the next overflow
        }
    }

    /// Puts an entry of a bucket at or above `base` into the ring or, beyond it, the overflow.
    #[inline]
    fn place(&mut self, bucket: u64, cell: u32) {
        if bucket - self.base < RING as u64 {
            self.ring[bucket as usize % RING].push(cell);
            self.in_ring += 1;
        } else {
            self.overflow_min = self.overflow_min.min(bucket);
            self.overflow.push((bucket, cell));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Against a list: every entry pushed comes out once, and each pop is from the lowest
        /// bucket holding entries (a key below the current bucket counting as in it), for
        /// keys near the last popped, equal to it, far beyond the window and rounding below it.
        #[test]
        fn pops_each_entry_once_from_the_lowest_bucket(
            steps in proptest::collection::vec((0.0..3.0 * WINDOW_CELLS, 0u8..4, 0u8..4), 1..300),
        ) {
            let mut queue = BucketQueue::default();
            queue.reset(1.0);
            let mut oracle: Vec<(u64, u32)> = Vec::new();
            let mut last = 1.0f64;
            for (k, &(offset, class, pops)) in steps.iter().enumerate() {
                let f = match class {
                    0 => last,
                    1 => last + offset / 16.0,
                    2 => last + offset,
                    _ => last - 1e-9,
                };
                queue.push(f, k as u32);
                oracle.push((bucket_of(f).max(queue.bucket()), k as u32));
                for _ in 0..pops {
                    let got = queue.pop();
                    let lowest = oracle.iter().map(|e| e.0).min();
                    match (got, lowest) {
                        (None, None) => {}
                        (Some(cell), Some(lowest)) => {
                            let at = oracle.iter().position(|e| e.1 == cell).expect("popped twice");
                            prop_assert_eq!(oracle[at].0, lowest);
                            prop_assert_eq!(queue.bucket(), lowest);
                            oracle.swap_remove(at);
                            last = last.max(lowest as f64 / BUCKETS_PER_CELL);
                        }
                        other => prop_assert!(false, "queue and oracle disagree: {other:?}"),
                    }
                }
            }
            while let Some(cell) = queue.pop() {
                let lowest = oracle.iter().map(|e| e.0).min().unwrap();
                let at = oracle.iter().position(|e| e.1 == cell).expect("popped twice");
                prop_assert_eq!(oracle[at].0, lowest);
                oracle.swap_remove(at);
            }
            prop_assert!(oracle.is_empty());
        }
    }
}
