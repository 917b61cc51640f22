//! Large buffers reused from one read to the next: decompressed chunks and the messages a
//! segmentation keeps between its passes. A fresh buffer costs a page fault and the kernel's
//! zeroing per 4 kB on its first use, and glibc hands big freed buffers back to the system
//! (or keeps them in another thread's arena): measured on `icms ingest` of 60 ten-second
//! sessions, 1 700 page faults per session and a tenth of the CPU. A pool holds a bounded
//! amount while idle ([`Pool::new`]'s `max_bytes`).

use std::sync::Mutex;

/// Buffers of `T` kept for reuse, at most `max_bytes` of capacity in all.
pub(crate) struct Pool<T> {
    buffers: Mutex<Vec<Vec<T>>>,
    max_bytes: usize,
    /// New buffers' capacity is a multiple of this (so that a buffer made for one chunk holds
    /// the next, a little bigger).
    granule: usize,
}

/// Decompressed chunks (and other large byte buffers of a read: an ingest's copy buffer) kept
/// between reads: 16 MiB, the chunks in flight of two reads at once (ours are about 1 MiB),
/// each made a multiple of 256 KiB.
pub(crate) static CHUNK_BUFFERS: Pool<u8> = Pool::new(16 << 20, 256 << 10);

/// Most buffers a pool keeps, whatever their size.
const MAX_BUFFERS: usize = 16;

impl<T> Pool<T> {
    /// An empty pool that keeps at most `max_bytes` of capacity, and makes new buffers of a
    /// multiple of `granule` elements (at least 1).
    pub(crate) const fn new(max_bytes: usize, granule: usize) -> Self {
        Pool {
            buffers: Mutex::new(Vec::new()),
            max_bytes,
            granule: if granule == 0 { 1 } else { granule },
        }
    }

    fn bytes(v: &Vec<T>) -> usize {
        v.capacity().saturating_mul(std::mem::size_of::<T>().max(1))
    }

    /// A buffer with room for at least `capacity` elements: the smallest pooled one that has
    /// it (its content as it was left: `clear` it, or overwrite it), or a new one.
    pub(crate) fn take(&self, capacity: usize) -> Vec<T> {
        let mut buffers = self.buffers.lock().unwrap_or_else(|e| e.into_inner());
        let best = buffers
            .iter()
            .enumerate()
            .filter(|(_, b)| b.capacity() >= capacity)
            .min_by_key(|(_, b)| b.capacity())
            .map(|(i, _)| i);
        match best {
            Some(i) => buffers.swap_remove(i),
            None => {
                drop(buffers);
                let rounded = capacity
                    .checked_next_multiple_of(self.granule)
                    .unwrap_or(capacity);
                Vec::with_capacity(rounded)
            }
        }
    }

    /// Takes `buffer` back for reuse, if it fits in what the pool may hold (else it is
    /// freed).
    pub(crate) fn give(&self, buffer: Vec<T>) {
        let size = Self::bytes(&buffer);
        if size == 0 || size > self.max_bytes {
            return;
        }
        let mut buffers = self.buffers.lock().unwrap_or_else(|e| e.into_inner());
        let held: usize = buffers.iter().map(Self::bytes).sum();
        if buffers.len() < MAX_BUFFERS && held + size <= self.max_bytes {
            buffers.push(buffer);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pool_hands_back_the_smallest_buffer_that_fits_and_keeps_no_more_than_its_bound() {
        let pool: Pool<u8> = Pool::new(1000, 1);
        pool.give(Vec::with_capacity(100));
        pool.give(Vec::with_capacity(400));
        pool.give(Vec::with_capacity(600)); // over the bound with the others: freed
        assert_eq!(pool.take(50).capacity(), 100);
        assert_eq!(pool.take(50).capacity(), 400);
        assert!(pool.take(50).capacity() >= 50);
        pool.give(Vec::with_capacity(2000)); // bigger than the bound
        assert_eq!(pool.take(1500).capacity(), 1500);
        let rounding: Pool<u8> = Pool::new(1000, 64);
        assert_eq!(rounding.take(65).capacity(), 128);
    }
}
