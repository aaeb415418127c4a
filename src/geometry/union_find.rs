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

/// Joins the connected components of the samples for which `member` holds, over a symmetric
/// adjacency in CSR form (`neighbor_start`, `neighbors`, as the mesh and the relief graph hold
/// it). Afterwards [`find_lowest`] (base 0) gives each member's component as its lowest member;
/// the entries of other samples are left as they were. `parent` holds one entry per sample.
///
/// The two halves of the samples are joined on their own, in parallel, then across: the sets,
/// and so their roots, are those of one pass over all, whatever the thread count. Every link
/// points to a lower sample, so one pass in index order labels every member with a single read:
/// at member `i`, `parent[i]` is `i` (a root) or a lower member, already labelled with its root.
pub fn join_components(
    neighbor_start: &[u32],
    neighbors: &[u32],
    member: &(impl Fn(usize) -> bool + Sync),
    parent: &mut [u32],
) {
    let n = parent.len();
    let half = n / 2;
    {
        let (low, high) = parent.split_at_mut(half);
        rayon::join(
            || join_block(neighbor_start, neighbors, member, low, 0),
            || join_block(neighbor_start, neighbors, member, high, half),
        );
    }
    for i in half..n {
        if !member(i) {
            continue;
        }
        for &j in &neighbors[neighbor_start[i] as usize..neighbor_start[i + 1] as usize] {
            if (j as usize) < half && member(j as usize) {
                union_lowest(parent, 0, i, j as usize);
            }
        }
    }
}

/// [`join_components`] on one block of the samples, `base..base + parent.len()`, along the
/// edges inside the block (`parent` holds global indices).
fn join_block(
    neighbor_start: &[u32],
    neighbors: &[u32],
    member: &(impl Fn(usize) -> bool + Sync),
    parent: &mut [u32],
    base: usize,
) {
    let end = base + parent.len();
    for i in base..end {
        if !member(i) {
            continue;
        }
        let mut ri = i;
        parent[i - base] = i as u32;
        for &j in &neighbors[neighbor_start[i] as usize..neighbor_start[i + 1] as usize] {
            let j = j as usize;
            if j >= i || j < base || !member(j) {
                continue;
            }
            // Most neighbours of a sample inside a set hang straight from the root `i` joined.
            if parent[j - base] as usize == ri {
                continue;
            }
            let rj = find_lowest(parent, base, j - base) + base;
            if rj < ri {
                parent[ri - base] = rj as u32;
                ri = rj;
            } else if rj > ri {
                parent[rj - base] = ri as u32;
            }
        }
    }
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
