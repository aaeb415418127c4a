//! The bucket queue of the relief's least-cost searches (the climate's moisture paths, the
//! coasts' shallow-water widths): samples filed by cost into buckets of a fixed width, handled
//! bucket after bucket, last in first out within one.
//!
//! The searches using it are label-correcting: a sample whose cost falls after it was handled
//! is filed again, and a sample popped from a bucket its current cost no longer falls in is
//! skipped ([`BucketQueue::pop`] does both checks' bookkeeping with the caller's cost). So the
//! costs come out the least path sums whatever the order within a bucket: those of a Dijkstra
//! search, as the sums are the same additions.

/// A bucket queue of sample indices (see the module documentation).
#[derive(Clone, Debug, Default)]
pub struct BucketQueue {
    buckets: Vec<Vec<u32>>,
    per_bucket: f64,
    last: usize,
    /// The bucket being handled.
    at: usize,
}

impl BucketQueue {
    /// Empties the queue (keeping its buffers) for buckets `width` wide; costs beyond
    /// `last` buckets go into the last one.
    pub fn reset(&mut self, width: f64, last: usize) {
        for b in &mut self.buckets {
            b.clear();
        }
        self.per_bucket = 1.0 / width;
        self.last = last;
        self.at = 0;
    }

    /// The bucket of `cost`.
    #[inline]
    pub fn bucket(&self, cost: f64) -> usize {
        ((cost * self.per_bucket) as usize).min(self.last)
    }

    /// Files sample `i` at `cost`.
    #[inline]
    pub fn push(&mut self, cost: f64, i: u32) {
        let k = self.bucket(cost);
        if k >= self.buckets.len() {
            self.buckets.resize_with(k + 1, Vec::new);
        }
        self.buckets[k].push(i);
    }

    /// The next sample to handle, with `cost_of` its cost now: samples filed under a bucket
    /// their cost has since left are skipped (they are handled from their new one). `None`
    /// once every bucket is empty.
    #[inline]
    pub fn pop(&mut self, cost_of: impl Fn(usize) -> f64) -> Option<usize> {
        while self.at < self.buckets.len() {
            while let Some(i) = self.buckets[self.at].pop() {
                let i = i as usize;
                if self.bucket(cost_of(i)) == self.at {
                    return Some(i);
                }
            }
            self.at += 1;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_come_out_by_bucket_and_stale_entries_are_skipped() {
        let mut q = BucketQueue::default();
        q.reset(1.0, 1 << 16);
        let mut cost = [5.5, 0.2, 3.0, 1e9];
        for (i, &c) in cost.iter().enumerate() {
            q.push(c, i as u32);
        }
        // Sample 0 improves to bucket 2: filed again; its old entry in bucket 5 is skipped.
        cost[0] = 2.5;
        q.push(cost[0], 0);
        let mut order = Vec::new();
        while let Some(i) = q.pop(|i| cost[i]) {
            order.push(i);
        }
        assert_eq!(order, vec![1, 0, 2, 3]);
        assert_eq!(q.bucket(1e9), 1 << 16);
    }
}
