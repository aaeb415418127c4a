//! Union–find whose every root is its set's lowest index (the higher root is always linked under
//! the lower), so that sets come out numbered in the order of their first member and a set's
//! label is known as soon as its lowest member is: the plates' pieces of a resampling, the
//! water bodies of the sea mask, the runs of a subduction front.
//!
//! `parent` holds indices offset by `base` (`parent[i] - base` is the parent of `i`), so that a
//! block of a larger array can be joined on its own with global indices in it.

/// The root of `x`: its set's lowest index. Halves the path on the way.
#[inline]
pub fn find_lowest(parent: &mut [u32], base: usize, mut x: usize) -> usize {
    loop {
        let p = parent[x] as usize - base;
        if p == x {
            return x;
        }
        let gp = parent[p] as usize - base;
        parent[x] = parent[p];
        if gp == p {
            return p;
        }
        x = gp;
    }
}

/// Joins the sets of `a` and `b`, the higher root linked under the lower; returns the root.
#[inline]
pub fn union_lowest(parent: &mut [u32], base: usize, a: usize, b: usize) -> usize {
    let (ra, rb) = (find_lowest(parent, base, a), find_lowest(parent, base, b));
    let (lo, hi) = if ra <= rb { (ra, rb) } else { (rb, ra) };
    if lo != hi {
        parent[hi] = (lo + base) as u32;
    }
    lo
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_are_the_lowest_members_with_and_without_an_offset() {
        for base in [0usize, 1000] {
            let mut parent: Vec<u32> = (0..10).map(|i| (i + base) as u32).collect();
            union_lowest(&mut parent, base, 7, 3);
            union_lowest(&mut parent, base, 9, 7);
            union_lowest(&mut parent, base, 5, 1);
            assert_eq!(union_lowest(&mut parent, base, 9, 5), 1);
            for i in [1, 3, 5, 7, 9] {
                assert_eq!(find_lowest(&mut parent, base, i), 1);
            }
            for i in [0, 2, 4, 6, 8] {
                assert_eq!(find_lowest(&mut parent, base, i), i);
            }
        }
    }
}
