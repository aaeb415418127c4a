//! Drainage network on the sample graph: single-flow-direction (steepest great-circle descent)
//! receivers, closed depressions resolved by a priority flood restricted to the basins of the
//! pits, a topological stack (receivers before donors) and drainage areas.
//!
//! Method:
//! 1. Receivers: each land sample drains to the neighbour of steepest descent
//!    S = (h_i − h_j) / d_ij (m/m; d_ij great-circle km); ocean samples stand at sea level (0 km)
//!    for this purpose, so a coastal sample drains to the sea rather than into a trench. This is
//!    the D8/"steepest descent" rule of O'Callaghan & Mark (1984) on an irregular graph. On a
//!    plain (steepest slope under [`PLAIN_SLOPE`], 1 m/km) the receiver is drawn instead among
//!    the lower neighbours at least [`PLAIN_SHARE`] as steep, in proportion to the slope, by a
//!    hash of the sample: steepest descent on a tilted plain sends every sample the same way,
//!    in parallel straight lines; drawn, the streams wander and join (Scheidegger 1967). The
//!    same draw picks receivers on the water surface below.
//! 2. Pits (land samples with no strictly lower neighbour) and the basins draining to them are
//!    found by walking receivers. Samples whose receiver chain reaches the ocean already have a
//!    monotone path to the sea, so their spill level equals their elevation; a
//!    Priority-Flood+ε (Barnes, Lehman & Mulla 2014, "Priority-flood: An optimal
//!    depression-filling and watershed-labeling algorithm", Computers & Geosciences 62) seeded
//!    from the boundary of the pit basins fills only those basins. Each flooded sample gets a
//!    water level strictly above the sample it was reached from (next representable f32), so
//!    the water surface descends strictly to the spill point; samples below their water level
//!    are *lakes*. The open set is a monotone radix heap, with a FIFO for flooded samples
//!    (Barnes et al.'s "improved" variant). Lake samples then drain to the sample that flooded
//!    them; other pit-basin samples keep their steepest receiver unless it now lies above them
//!    on the water surface, in which case they take the steepest descent on it. Every lake
//!    thus leads to its outlet and on to the sea (no cycles: the water surface strictly
//!    decreases along receivers).
//! 3. Stack: breadth-first from the outlets over the donor lists (Braun & Willett 2013,
//!    "A very efficient O(n), implicit and parallel method to solve the stream power equation
//!    governing fluvial incision and landscape evolution", Geomorphology 180–181), so every
//!    sample comes after its receiver.
//! 4. Drainage area A_i = Σ_upstream a_j·p_j (km²; p relative precipitation, 1 by default),
//!    accumulated in reverse stack order.
//!
//! 5. Water balance (when [`Drainage::lake_area_ratio`] is set): a lake keeps at most
//!    ratio × its catchment of area (runoff over net evaporation: a closed lake stands where
//!    the inflow of its catchment equals the net evaporation from its surface). Outlets are visited upstream first; a lake over
//!    its balance is *closed*: its catchment is taken off everything below its outlet, its
//!    basin (everything draining through the outlet) is flooded again from its lowest sample,
//!    which becomes a sink, and the lake is the first samples of that flood up to the balance
//!    area, at the level of the last of them. Stack and areas are then rebuilt. Hollows of the
//!    basin beyond the lake stay dry; their water goes over their rims to the lake, each sample
//!    to a neighbour the flood reached before it, lower on the flood's water surface (not the
//!    flood's own parents, which cross a hollow's floor in straight parallel lines).
//!
//! A land region with no route to any ocean sample (e.g. a planet without sea) drains to its
//! lowest sample, which becomes an endorheic sink (receiver = itself, recorded in `sinks`), as
//! does the low point of a closed lake.
//!
//! Cost: O(n) for receivers, stack and areas, plus O(k log k) for the k samples in pit basins.
//! Deterministic: ties go to the lowest neighbour position in the CSR list, the flood breaks
//! ties by sample index, and all sums are sequential in stack order.

use std::collections::VecDeque;

use rayon::prelude::*;

use super::graph::{ReliefGraph, inv_km};
use crate::geometry::order_bits;

/// Result and scratch space of [`Drainage::compute`]; reuse one across steps to avoid
/// allocations.
#[derive(Clone, Debug, Default)]
pub struct Drainage {
    /// Downstream sample of each land sample (a land or an ocean sample); ocean samples and
    /// endorheic sinks point to themselves.
    pub receiver: Vec<u32>,
    /// Great-circle distance to the receiver, km (0 where the receiver is the sample itself).
    pub receiver_km: Vec<f32>,
    /// Land samples ordered so that every sample comes after its receiver (breadth-first from
    /// the outlets). Contains every land sample exactly once.
    pub stack: Vec<u32>,
    /// Land: precipitation-weighted drainage area including the sample itself, km².
    /// Ocean: total drainage area of the rivers that end in this sample (0 if none).
    pub area_km2: Vec<f64>,
    /// Land: water surface, km (the lake level where the sample lies in a filled depression,
    /// otherwise its elevation). Ocean: 0 (sea level).
    pub water_level_km: Vec<f32>,
    /// True for ocean samples (copy of the mask used).
    pub ocean: Vec<bool>,
    /// Endorheic sinks: land samples without any route to the sea, and the low points of closed
    /// lakes (their receiver is themselves). Sorted.
    pub sinks: Vec<u32>,
    /// Number of pits found before flooding (land samples with no lower neighbour).
    pub pit_count: usize,
    /// Number of land samples in flooded depressions (water level above the elevation).
    pub lake_sample_count: usize,
    /// Number of samples in pit basins (the flooded region).
    pub region_count: usize,
    /// Wall time of the sub-passes of the last call, ms, in the order of
    /// [`Drainage::STAGES`].
    pub timings_ms: [f64; 6],
    /// Water balance of closed depressions: the largest lake area a catchment keeps, per km² of
    /// (precipitation-weighted) catchment, i.e. runoff / net evaporation from the lake surface.
    /// A lake whose area at its spill point exceeds this share of its catchment is *closed*:
    /// it shrinks until it does not (its level falls), no water leaves it, and its basin drains
    /// to its lowest sample (a sink). `None`: every depression fills to its spill point.
    pub lake_area_ratio: Option<f64>,
    /// Closed lakes of the last call: (sink, start, end) into `closed_members`, by sink.
    closed: Vec<(u32, u32, u32)>,
    /// Lake samples of the closed lakes (see `closed`).
    closed_members: Vec<u32>,
    // Scratch.
    h: Vec<f32>,
    donor_start: Vec<u32>,
    donors: Vec<u32>,
    region: Vec<u32>,
    /// Per-sample state during one call (0 untouched; see `IN_REGION` etc.), reset before
    /// returning, so it stays small (u8) and cache-resident.
    mark: Vec<u8>,
    seeds: Vec<u32>,
    path: Vec<u32>,
    parent: Vec<u32>,
    land: Vec<u32>,
    fill: Vec<u32>,
    heap: RadixHeap,
    pit_queue: VecDeque<u32>,
    lake_acc: Vec<f64>,
    closing: Vec<(u32, f64)>,
    basin: Vec<u32>,
    order: Vec<u32>,
    pos: Vec<u32>,
    slots: Vec<u32>,
    /// Position of each sample in the flood order of the basin being closed (`u32::MAX`
    /// outside it).
    flood_rank: Vec<u32>,
}

const IN_REGION: u8 = 1;
const DONE: u8 = 2;
const TO_SEA: u8 = 3;
const SEED: u8 = 4;
const BASIN: u8 = 5;
const CLOSED: u8 = 6;

/// Relative precipitation at sample `i` (1 without a field or where it is not finite; never
/// negative).
#[inline]
fn rain_at(precipitation: Option<&[f32]>, i: usize) -> f64 {
    precipitation
        .and_then(|p| p.get(i).copied())
        .filter(|p| p.is_finite())
        .unwrap_or(1.0)
        .max(0.0) as f64
}

/// The f32 whose [`order_bits`] key is `b`.
#[inline]
fn level_of_bits(b: u32) -> f32 {
    f32::from_bits(if b >> 31 == 1 { b & 0x7fff_ffff } else { !b })
}

/// Monotone priority queue on u32 keys (a radix heap, Ahuja, Mehlhorn, Orlin & Tarjan 1990):
/// valid when no key smaller than the last popped one is pushed, which holds in the priority
/// flood (levels only rise). Amortised O(log key range) per item, but in practice each item is
/// moved a couple of times, several times faster than a binary heap. Ties pop in LIFO order.
#[derive(Clone, Debug, Default)]
struct RadixHeap {
    last: u32,
    len: usize,
    buckets: Vec<Vec<(u32, u32)>>,
}

impl RadixHeap {
    #[inline]
    fn bucket(&self, key: u32) -> usize {
        (32 - (key ^ self.last).leading_zeros()) as usize
    }

    fn clear(&mut self) {
        self.buckets.resize_with(33, Vec::new);
        for b in &mut self.buckets {
            b.clear();
        }
        self.len = 0;
        self.last = 0;
    }

    /// Pushes `(key, value)`; a key below the last popped one is clamped up to it (cannot
    /// happen in the flood, but keeps the structure valid).
    #[inline]
    fn push(&mut self, key: u32, value: u32) {
        if self.buckets.len() < 33 {
            self.buckets.resize_with(33, Vec::new);
        }
        let key = key.max(self.last);
        let b = self.bucket(key);
        self.buckets[b].push((key, value));
        self.len += 1;
    }

    /// Restarts the key range (only when empty): the next pushes may be below the last pop.
    fn reset_floor(&mut self, key: u32) {
        if self.len == 0 {
            self.last = key;
        }
    }

    fn pop(&mut self) -> Option<(u32, u32)> {
        if self.len == 0 || self.buckets.len() < 33 {
            return None;
        }
        if self.buckets[0].is_empty() {
            let k = (1..33).find(|&k| !self.buckets[k].is_empty())?;
            let items = std::mem::take(&mut self.buckets[k]);
            self.last = items.iter().map(|x| x.0).min().unwrap_or(self.last);
            for &(key, v) in &items {
                let b = self.bucket(key);
                self.buckets[b].push((key, v));
            }
            // Give the emptied bucket its storage back.
            let mut items = items;
            items.clear();
            if self.buckets[k].is_empty() {
                self.buckets[k] = items;
            }
        }
        self.len -= 1;
        self.buckets[0].pop()
    }
}

impl Drainage {
    /// The names [`Self::timings_ms`] are recorded under in the step timings: receivers, pit
    /// basins, flood, stack, areas, lakes' water balance.
    pub const STAGES: [&'static str; 6] = [
        "drainage_receivers",
        "drainage_pit_basins",
        "drainage_flood",
        "drainage_stack",
        "drainage_areas",
        "drainage_lake_balance",
    ];

    /// Empty drainage; buffers grow on the first [`Drainage::compute`].
    pub fn new() -> Self {
        Self::default()
    }

    /// True where sample `i` lies under a lake (water level above its elevation).
    #[inline]
    pub fn is_lake(&self, i: usize) -> bool {
        !self.ocean[i] && self.water_level_km[i] > self.h[i]
    }

    /// Lake depth at sample `i`, km (0 outside lakes and in the ocean).
    #[inline]
    pub fn lake_depth_km(&self, i: usize) -> f32 {
        if self.ocean[i] {
            0.0
        } else {
            (self.water_level_km[i] - self.h[i]).max(0.0)
        }
    }

    /// The lake samples of the closed lake whose sink is `sink` (see
    /// [`Drainage::lake_area_ratio`]); `None` when `sink` is not the sink of a closed lake.
    pub fn closed_lake_samples(&self, sink: usize) -> Option<&[u32]> {
        let k = self
            .closed
            .binary_search_by_key(&(sink as u32), |c| c.0)
            .ok()?;
        let (_, a, b) = self.closed[k];
        Some(&self.closed_members[a as usize..b as usize])
    }

    /// Number of closed lakes in the last computation (see [`Drainage::lake_area_ratio`]).
    pub fn closed_lake_count(&self) -> usize {
        self.closed.len()
    }

    /// Builds the network for surface `elevation_km` (km, sea level 0) with `ocean` marking sea
    /// samples. `precipitation` (relative, dimensionless, ≥ 0; `None` = uniform 1) weights each
    /// sample's contribution to drainage area. Slices shorter than the graph are read as ocean /
    /// elevation 0 / precipitation 1; NaN elevations as 0.
    pub fn compute(
        &mut self,
        g: &ReliefGraph,
        elevation_km: &[f32],
        ocean: &[bool],
        precipitation: Option<&[f32]>,
    ) {
        self.compute_routes(g, elevation_km, ocean);
        self.compute_areas(g, precipitation);
    }

    /// The first part of [`Self::compute`], which does not read the rain: receivers, pits,
    /// lakes and the stack (steps 1 to 3). [`Self::compute_areas`] must follow.
    pub fn compute_routes(&mut self, g: &ReliefGraph, elevation_km: &[f32], ocean: &[bool]) {
        let n = g.len();
        let mut lap = super::lap_timer();
        self.receiver.resize(n, 0);
        self.receiver_km.resize(n, 0.0);
        self.area_km2.resize(n, 0.0);
        self.water_level_km.resize(n, 0.0);
        self.ocean.resize(n, true);
        self.h.resize(n, 0.0);
        self.mark.resize(n, 0);
        self.parent.resize(n, u32::MAX);
        self.sinks.clear();
        self.closed.clear();
        self.closed_members.clear();

        // Sanitised inputs: routing height (ocean at sea level) and mask.
        const CH: usize = 8192;
        self.h
            .par_chunks_mut(CH)
            .zip(self.ocean.par_chunks_mut(CH))
            .zip(self.water_level_km.par_chunks_mut(CH))
            .enumerate()
            .for_each(|(c, ((h, o), w))| {
                let base = c * CH;
                for k in 0..h.len() {
                    let i = base + k;
                    let is_ocean = ocean.get(i).copied().unwrap_or(true);
                    let z = elevation_km.get(i).copied().unwrap_or(0.0);
                    o[k] = is_ocean;
                    let hz = if is_ocean || !z.is_finite() { 0.0 } else { z };
                    h[k] = hz;
                    w[k] = hz;
                }
            });

        // 1. Steepest-descent receivers (parallel, per-sample: deterministic).
        {
            let h = &self.h;
            let oc = &self.ocean;
            self.receiver
                .par_chunks_mut(CH)
                .zip(self.receiver_km.par_chunks_mut(CH))
                .enumerate()
                .for_each(|(c, (rs, ds))| {
                    let base = c * CH;
                    for k in 0..rs.len() {
                        let i = base + k;
                        let (mut r, mut d) = (i as u32, 0.0f32);
                        if !oc[i] {
                            let hi = h[i];
                            let (a, b) = (
                                g.neighbor_start[i] as usize,
                                g.neighbor_start[i + 1] as usize,
                            );
                            let (nb, len) = (&g.neighbors[a..b], &g.edge_km[a..b]);
                            // 1/length = 0 for degenerate edges: slope 0, never chosen.
                            let slope = |k: usize| (hi - h[nb[k] as usize]) * inv_km(len[k]);
                            // The slopes are kept for a plain's draw (up to 16 neighbours; a
                            // sample with more computes them again).
                            let mut kept = [0.0f32; 16];
                            let (mut best, mut best_k) = (0.0f32, 0);
                            for k in 0..nb.len() {
                                let s = slope(k);
                                if let Some(slot) = kept.get_mut(k) {
                                    *slot = s;
                                }
                                // The strict `>` keeps the first of equal slopes.
                                if s > best {
                                    best = s;
                                    best_k = k;
                                }
                            }
                            if best > 0.0 {
                                if best < PLAIN_SLOPE {
                                    best_k = match kept.get(..nb.len()) {
                                        Some(kept) => {
                                            plain_draw(i, (best, best_k), || kept.iter().copied())
                                        }
                                        None => plain_draw(i, (best, best_k), || {
                                            (0..nb.len()).map(slope)
                                        }),
                                    };
                                }
                                r = nb[best_k];
                                d = g.edge_km[a + best_k];
                            }
                        }
                        rs[k] = r;
                        ds[k] = d;
                    }
                });
        }
        self.land.clear();
        self.land
            .extend((0..n as u32).filter(|&i| !self.ocean[i as usize]));
        self.timings_ms[0] = lap();

        // 2. Pits and their basins.
        self.pit_count = self
            .land
            .iter()
            .filter(|&&i| self.receiver[i as usize] == i)
            .count();
        self.region.clear();
        self.timings_ms[1] = 0.0;
        if self.pit_count > 0 {
            self.collect_pit_basins();
            self.timings_ms[1] = lap();
            self.flood(g);
            // Lake samples drain to the sample that flooded them (strictly lower water level,
            // towards the outlet). Other pit-basin samples keep their steepest-descent receiver
            // when it is still strictly lower on the water surface, else take the steepest
            // descent on the water surface (rim samples next to a lake).
            let done = DONE;
            for k in 0..self.region.len() {
                let i = self.region[k] as usize;
                let li = self.water_level_km[i];
                if li > self.h[i] {
                    let pa = self.parent[i];
                    if pa != u32::MAX {
                        let d = g
                            .edges(i)
                            .find(|&e| g.neighbors[e] == pa)
                            .map(|e| g.edge_km[e])
                            .unwrap_or(0.0);
                        self.receiver[i] = pa;
                        self.receiver_km[i] = d;
                        continue;
                    }
                }
                if self.parent[i] == u32::MAX {
                    continue; // endorheic sink
                }
                let r0 = self.receiver[i] as usize;
                let level = |j: usize| -> f32 {
                    if self.mark[j] == done {
                        self.water_level_km[j]
                    } else {
                        self.h[j]
                    }
                };
                if r0 != i && level(r0) < li {
                    continue;
                }
                let cands = || {
                    g.edges(i).filter(|&e| g.edge_km[e] > 0.0).map(|e| {
                        let j = g.neighbors[e] as usize;
                        (j as u32, (li - level(j)) / g.edge_km[e], g.edge_km[e])
                    })
                };
                let (r, d) = pick_receiver(i, cands).unwrap_or((i as u32, 0.0));
                self.receiver[i] = r;
                self.receiver_km[i] = d;
            }
        }
        self.region_count = self.region.len();
        self.lake_sample_count = self
            .region
            .iter()
            .filter(|&&i| self.water_level_km[i as usize] > self.h[i as usize])
            .count();
        // Reset the marks (land samples and flood seeds only were touched).
        for &i in &self.land {
            self.mark[i as usize] = 0;
        }
        for &i in &self.seeds {
            self.mark[i as usize] = 0;
        }
        self.seeds.clear();
        self.timings_ms[2] = lap();

        // 3. Donor lists and the stack.
        self.stack(g);
        self.timings_ms[3] = lap();
    }

    /// The second part of [`Self::compute`], after [`Self::compute_routes`]: drainage areas
    /// weighted by `precipitation` and the lakes' water balance (steps 4 and 5).
    pub fn compute_areas(&mut self, g: &ReliefGraph, precipitation: Option<&[f32]>) {
        let clock = std::time::Instant::now();
        self.areas(g, precipitation);
        self.timings_ms[4] = clock.elapsed().as_secs_f64() * 1e3;

        // 5. Water balance: a lake whose catchment cannot keep it full to its spill point
        //    shrinks to the area its inflow can feed and no longer overflows.
        self.timings_ms[5] = 0.0;
        if let Some(ratio) = self.lake_area_ratio
            && self.lake_sample_count > 0
        {
            let clock = std::time::Instant::now();
            self.balance_lakes(g, ratio, precipitation);
            self.timings_ms[5] = clock.elapsed().as_secs_f64() * 1e3;
        }
    }

    /// Donor lists (CSR, in sample order) and the stack (breadth-first from the outlets), from
    /// the receivers.
    fn stack(&mut self, g: &ReliefGraph) {
        let n = g.len();
        // Donor lists and the stack.
        self.donor_start.clear();
        self.donor_start.resize(n + 1, 0);
        for &i in &self.land {
            let r = self.receiver[i as usize] as usize;
            if r != i as usize {
                self.donor_start[r + 1] += 1;
            }
        }
        for i in 0..n {
            self.donor_start[i + 1] += self.donor_start[i];
        }
        self.donors.resize(self.donor_start[n] as usize, 0);
        self.fill.clear();
        self.fill.extend_from_slice(&self.donor_start[..n]);
        self.stack.clear();
        for &i in &self.land {
            let r = self.receiver[i as usize] as usize;
            if r != i as usize {
                self.donors[self.fill[r] as usize] = i;
                self.fill[r] += 1;
            }
            if r == i as usize || self.ocean[r] {
                self.stack.push(i);
            }
        }
        let mut head = 0;
        while head < self.stack.len() {
            let i = self.stack[head] as usize;
            head += 1;
            let (a, b) = (
                self.donor_start[i] as usize,
                self.donor_start[i + 1] as usize,
            );
            self.stack.extend_from_slice(&self.donors[a..b]);
        }
    }

    /// Drainage areas (reverse stack order, sequential f64), from the receivers and the stack.
    fn areas(&mut self, g: &ReliefGraph, precipitation: Option<&[f32]>) {
        self.area_km2.iter_mut().for_each(|a| *a = 0.0);
        for &i in &self.land {
            let i = i as usize;
            self.area_km2[i] = g.area_km2[i] * rain_at(precipitation, i);
        }
        for k in (0..self.stack.len()).rev() {
            let i = self.stack[k] as usize;
            let r = self.receiver[i] as usize;
            if r != i {
                self.area_km2[r] += self.area_km2[i];
            }
        }
    }

    /// Step 5 of [`Self::compute`]: closes the lakes whose catchment cannot keep them full
    /// (lake area at the spill point > `ratio` × catchment area), upstream first, so that a
    /// closed lake's catchment no longer counts for the lakes below it. The stack and the
    /// areas are patched in the closed basins only (see [`Self::close_lake`]); the donor lists
    /// are left as they were (only this step reads them).
    fn balance_lakes(&mut self, g: &ReliefGraph, ratio: f64, precipitation: Option<&[f32]>) {
        let n = g.len();
        self.lake_acc.clear();
        self.lake_acc.resize(n, 0.0);
        self.closing.clear();
        for k in (0..self.stack.len()).rev() {
            let i = self.stack[k] as usize;
            if !self.is_lake(i) {
                continue;
            }
            self.lake_acc[i] += g.area_km2[i];
            let r = self.receiver[i] as usize;
            if r == i {
                continue; // an endorheic sink: nothing leaves it already
            }
            if self.is_lake(r) {
                self.lake_acc[r] += self.lake_acc[i];
                continue;
            }
            // `i` is the outlet of a lake (or of the part of a lake behind an island).
            let catchment = self.area_km2[i];
            if self.lake_acc[i] <= ratio * catchment {
                continue;
            }
            self.closing.push((i as u32, catchment));
            let mut j = r;
            loop {
                self.area_km2[j] -= catchment;
                let rj = self.receiver[j] as usize;
                if rj == j {
                    break;
                }
                j = rj;
            }
        }
        if self.closing.is_empty() {
            return;
        }
        self.pos.resize(n, 0);
        for (k, &i) in self.stack.iter().enumerate() {
            self.pos[i as usize] = k as u32;
        }
        for c in 0..self.closing.len() {
            let (o, catchment) = self.closing[c];
            self.close_lake(g, o as usize, ratio * catchment, precipitation);
        }
        // Marks back to 0 (every closed basin lies in the pit-basin region).
        for &i in &self.region {
            self.mark[i as usize] = 0;
        }
        self.sinks.sort_unstable();
        self.closed.sort_unstable_by_key(|c| c.0);
        self.lake_sample_count = self
            .region
            .iter()
            .filter(|&&i| self.water_level_km[i as usize] > self.h[i as usize])
            .count();
    }

    /// Closes the lake whose outlet is `o`: its basin (every sample draining through `o`, not
    /// already in a closed basin) is flooded again from its lowest sample, which becomes a sink;
    /// the lake is the first samples of that flood up to `target_km2` of area, at the level of
    /// the last of them. Lake samples drain to the sample that flooded them; the others keep
    /// their receiver where it is still lower on the new water surface, else take the steepest
    /// descent on it within the basin.
    ///
    /// The flood visits the basin in order of its final water surface, so every sample comes
    /// after its receiver: the basin's samples take the basin's stack positions (a set: the
    /// subtree of the outlet) in flood order, and their drainage areas are summed again along
    /// it. Nothing else drains into the basin, and what is below the outlet already lost the
    /// catchment (in [`Self::balance_lakes`]).
    fn close_lake(
        &mut self,
        g: &ReliefGraph,
        o: usize,
        target_km2: f64,
        precipitation: Option<&[f32]>,
    ) {
        // The basin: the subtree of the outlet.
        self.basin.clear();
        self.basin.push(o as u32);
        self.mark[o] = BASIN;
        let mut head = 0;
        while head < self.basin.len() {
            let i = self.basin[head] as usize;
            head += 1;
            let (a, b) = (
                self.donor_start[i] as usize,
                self.donor_start[i + 1] as usize,
            );
            for k in a..b {
                let d = self.donors[k] as usize;
                if self.mark[d] == 0 {
                    self.mark[d] = BASIN;
                    self.basin.push(d as u32);
                }
            }
        }
        let mut s = o;
        for &i in &self.basin {
            let i = i as usize;
            if self.h[i] < self.h[s] || (self.h[i] == self.h[s] && i < s) {
                s = i;
            }
        }
        // Priority-Flood+ε within the basin from its lowest sample.
        let hs = self.h[s];
        self.heap.clear();
        self.pit_queue.clear();
        self.heap.reset_floor(order_bits(hs));
        self.mark[s] = CLOSED;
        self.parent[s] = u32::MAX;
        self.water_level_km[s] = hs;
        self.heap.push(order_bits(hs), s as u32);
        self.order.clear();
        let (mut lake_area, mut level, mut lake_n) = (0.0f64, hs, 0usize);
        while let Some((c, lc)) = self.flood_pop() {
            self.order.push(c as u32);
            if lake_area < target_km2 {
                lake_area += g.area_km2[c];
                level = lc;
                lake_n = self.order.len();
            }
            self.flood_neighbours(g, c, lc, BASIN, CLOSED);
        }
        // The lake: the first `lake_n` samples, at `level`.
        let start = self.closed_members.len() as u32;
        for k in 0..lake_n {
            let i = self.order[k] as usize;
            self.water_level_km[i] = level.max(self.h[i]);
            if self.water_level_km[i] > self.h[i] {
                self.closed_members.push(i as u32);
            }
        }
        self.closed
            .push((s as u32, start, self.closed_members.len() as u32));
        self.sinks.push(s as u32);
        // Receivers.
        let edge_to = |g: &ReliefGraph, i: usize, j: u32| -> f32 {
            g.edges(i)
                .find(|&e| g.neighbors[e] == j)
                .map(|e| g.edge_km[e])
                .unwrap_or(0.0)
        };
        // A receiver must come before its donor in the flood order (which becomes the stack
        // order): the flood's ε-raised pit samples can be popped before a sample whose water
        // level is lower.
        self.flood_rank.resize(g.len(), u32::MAX);
        for (k, &i) in self.order.iter().enumerate() {
            self.flood_rank[i as usize] = k as u32;
        }
        for k in 0..self.order.len() {
            let i = self.order[k] as usize;
            if i == s {
                self.receiver[i] = i as u32;
                self.receiver_km[i] = 0.0;
                continue;
            }
            let li = self.water_level_km[i];
            let pa = self.parent[i];
            // The lake drains along its flood. A hollow beyond it (its level raised to its rim by
            // the flood, above its floor) drains over its rim too, but by the water surface,
            // not the flood's parents, which run in straight parallel lines across its floor.
            if k < lake_n {
                self.receiver[i] = pa;
                self.receiver_km[i] = edge_to(g, i, pa);
                continue;
            }
            let before = |j: usize| (self.flood_rank[j] as usize) < k;
            let r0 = self.receiver[i] as usize;
            if self.mark[r0] == CLOSED && self.water_level_km[r0] < li && r0 != i && before(r0) {
                continue;
            }
            let cands = || {
                g.edges(i)
                    .filter(|&e| {
                        let j = g.neighbors[e] as usize;
                        g.edge_km[e] > 0.0 && self.mark[j] == CLOSED && before(j)
                    })
                    .map(|e| {
                        let j = g.neighbors[e] as usize;
                        let dist = g.edge_km[e];
                        (j as u32, (li - self.water_level_km[j]) / dist, dist)
                    })
            };
            let (r, d) = pick_receiver(i, cands).unwrap_or_else(|| (pa, edge_to(g, i, pa)));
            self.receiver[i] = r;
            self.receiver_km[i] = d;
        }
        // Stack positions and drainage areas of the basin.
        self.slots.clear();
        self.slots
            .extend(self.order.iter().map(|&i| self.pos[i as usize]));
        self.slots.sort_unstable();
        for k in 0..self.order.len() {
            let (i, p) = (self.order[k], self.slots[k]);
            self.stack[p as usize] = i;
            self.pos[i as usize] = p;
            self.area_km2[i as usize] = g.area_km2[i as usize] * rain_at(precipitation, i as usize);
        }
        for k in (0..self.order.len()).rev() {
            let i = self.order[k] as usize;
            let r = self.receiver[i] as usize;
            if r != i {
                self.area_km2[r] += self.area_km2[i];
            }
        }
        // Hollows of the basin beyond its lake hold no water either: the basin's balance that
        // shrank the lake leaves them dry (their runoff goes on down the flood's receivers,
        // over their rims, to the lake), where the flood would have filled them to their rims.
        for &i in &self.order[lake_n.min(self.order.len())..] {
            let i = i as usize;
            self.water_level_km[i] = self.h[i];
        }
        for &i in &self.order {
            self.flood_rank[i as usize] = u32::MAX;
        }
    }

    /// Marks every land sample whose receiver chain ends in a pit (mark = epoch) and lists them
    /// in `region` (in a deterministic order: land order, then down each receiver chain).
    fn collect_pit_basins(&mut self) {
        let (in_region, to_sea) = (IN_REGION, TO_SEA);
        for k in 0..self.land.len() {
            let start = self.land[k] as usize;
            if self.mark[start] == in_region || self.mark[start] == to_sea {
                continue;
            }
            self.path.clear();
            let mut i = start;
            let verdict = loop {
                let m = self.mark[i];
                if m == in_region || m == to_sea {
                    break m;
                }
                self.path.push(i as u32);
                let r = self.receiver[i] as usize;
                if r == i {
                    break in_region;
                }
                if self.ocean[r] {
                    break to_sea;
                }
                if self.path.len() > self.land.len() {
                    break in_region; // cannot happen (strict descent), but never loop forever
                }
                i = r;
            };
            for &p in &self.path {
                self.mark[p as usize] = verdict;
            }
            if verdict == in_region {
                self.region.extend_from_slice(&self.path);
            }
        }
    }

    /// The next sample of a priority flood and its water level: flooded samples (the FIFO)
    /// first, then the lowest of the open set.
    #[inline]
    fn flood_pop(&mut self) -> Option<(usize, f32)> {
        if let Some(c) = self.pit_queue.pop_front() {
            Some((c as usize, self.water_level_km[c as usize]))
        } else {
            self.heap.pop().map(|(k, c)| (c as usize, level_of_bits(k)))
        }
    }

    /// Floods the neighbours of `c` (water level `lc`) marked `from`: marks them `to`, makes
    /// `c` their parent, and queues them at their water level (just above `lc` when they lie
    /// below it, in the FIFO; their own elevation otherwise). Returns how many.
    #[inline]
    fn flood_neighbours(&mut self, g: &ReliefGraph, c: usize, lc: f32, from: u8, to: u8) -> usize {
        let mut count = 0;
        for e in g.edges(c) {
            let j = g.neighbors[e] as usize;
            if self.mark[j] != from {
                continue;
            }
            self.mark[j] = to;
            self.parent[j] = c as u32;
            count += 1;
            let hj = self.h[j];
            let up = lc.next_up();
            if hj <= up {
                self.water_level_km[j] = up.max(hj);
                self.pit_queue.push_back(j as u32);
            } else {
                self.water_level_km[j] = hj;
                self.heap.push(order_bits(hj), j as u32);
            }
        }
        count
    }

    /// Priority-Flood+ε over the pit basins, seeded from their boundary.
    fn flood(&mut self, g: &ReliefGraph) {
        let (in_region, done, seed) = (IN_REGION, DONE, SEED);
        self.heap.clear();
        self.pit_queue.clear();
        // Seeds: non-region neighbours of region samples, at their own spill level (their
        // elevation: they have a descending path to the sea; sea level for ocean samples).
        for k in 0..self.region.len() {
            let i = self.region[k] as usize;
            for e in g.edges(i) {
                let j = g.neighbors[e] as usize;
                let m = self.mark[j];
                if m == in_region || m == done || m == seed {
                    continue;
                }
                self.mark[j] = seed;
                self.seeds.push(j as u32);
                self.heap.push(order_bits(self.h[j]), j as u32);
            }
        }
        let mut remaining = self.region.len();
        loop {
            while remaining > 0 {
                let Some((c, lc)) = self.flood_pop() else {
                    break;
                };
                remaining -= self.flood_neighbours(g, c, lc, in_region, done);
            }
            if remaining == 0 {
                break;
            }
            // Region samples with no route to the sea: the lowest becomes an endorheic sink.
            let mut best: Option<(f32, u32)> = None;
            for &i in &self.region {
                if self.mark[i as usize] == in_region {
                    let hi = self.h[i as usize];
                    if best.is_none_or(|(b, bi)| hi < b || (hi == b && i < bi)) {
                        best = Some((hi, i));
                    }
                }
            }
            let Some((hs, s)) = best else { break };
            self.mark[s as usize] = done;
            self.parent[s as usize] = u32::MAX;
            remaining -= 1;
            self.water_level_km[s as usize] = hs;
            self.sinks.push(s);
            self.heap.reset_floor(order_bits(hs));
            self.heap.push(order_bits(hs), s);
        }
        self.sinks.sort_unstable();
    }
}

/// Sea mask: the samples at or below sea level (elevation ≤ 0 km) that are open sea. Samples at
/// or below sea level form connected bodies of water; a body is sea when it holds a sample
/// flagged in `always_sea` (typically oceanic crust) and covers at least `min_sea_area_km2`.
/// Any other body (a continental depression, or a speck of ocean floor walled in by land) stays
/// land, so the drainage pass turns it into a lake that fills and overflows (the Caspian and the
/// Dead Sea are land basins, not ocean); otherwise one such speck would take the sediment of the
/// land around it. NaN counts as sea level.
///
/// Allocates its scratch; [`sea_mask_with`] reuses one.
pub fn sea_mask(
    g: &ReliefGraph,
    elevation_km: &[f32],
    always_sea: &[bool],
    min_sea_area_km2: f64,
    out: &mut Vec<bool>,
) {
    sea_mask_with(
        g,
        elevation_km,
        always_sea,
        min_sea_area_km2,
        out,
        &mut SeaMaskScratch::default(),
    );
}

/// Reusable buffers of [`sea_mask_with`] (grow to the graph size on first use).
#[derive(Clone, Debug, Default)]
pub struct SeaMaskScratch {
    /// Union–find parent per sample at or below sea level (after the labelling pass: the
    /// body's smallest sample index).
    parent: Vec<u32>,
    /// Per body (at its smallest index): area summed in index order, km².
    area: Vec<f64>,
    /// Per body (at its smallest index): `OPEN` and `SEA` bits.
    flags: Vec<u8>,
    queue: Vec<u32>,
    seen: Vec<bool>,
    /// Per sample: at or below sea level (computed once, in parallel).
    below: Vec<bool>,
}

const OPEN: u8 = 1;
const SEA: u8 = 2;

/// Steepest slope (m/m) under which a land sample counts as lying on a plain: its receiver is
/// drawn among the lower neighbours nearly as steep (see `pick_receiver`). Lowland rivers
/// fall 0.1–1 m per km.
pub const PLAIN_SLOPE: f32 = 1.0e-3;

/// Share of the steepest slope a neighbour must offer to be a plain sample's receiver.
pub const PLAIN_SHARE: f32 = 0.5;

/// The receiver of sample `i` among the neighbours `cands()` lists as (neighbour, slope m/m,
/// edge km), or `None` when none lies lower (slope > 0): the steepest descent (the first of
/// equal slopes), except on a plain (steepest slope under [`PLAIN_SLOPE`]), where it is drawn
/// by [`plain_draw`]. `cands` is called again for the draw (no buffer).
#[inline]
fn pick_receiver<I: Iterator<Item = (u32, f32, f32)>>(
    i: usize,
    cands: impl Fn() -> I,
) -> Option<(u32, f32)> {
    let mut best: Option<(usize, f32)> = None;
    for (k, (_, s, _)) in cands().enumerate() {
        if s > 0.0 && best.is_none_or(|b| s > b.1) {
            best = Some((k, s));
        }
    }
    let (mut k, bs) = best?;
    if bs < PLAIN_SLOPE {
        k = plain_draw(i, (bs, k), || cands().map(|c| c.1));
    }
    cands().nth(k).map(|(j, _, km)| (j, km))
}

/// The receiver of plain sample `i`, whose steepest slope to a lower neighbour is `best` (> 0,
/// under [`PLAIN_SLOPE`]; the first neighbour that steep is at position `best_k` of `slopes()`):
/// drawn with weights in proportion to the slope among the neighbours at least [`PLAIN_SHARE`]
/// as steep, by a hash of the sample (the same draw every step). Returns the chosen position.
/// On a tilted plane (a basin's filled floor tilted by isostasy), steepest descent sends every
/// sample the same way, and the rivers come out as parallel straight lines; drawn like this
/// they wander and join, as random-walk networks do (Scheidegger 1967).
#[inline]
fn plain_draw<S: Iterator<Item = f32>>(
    i: usize,
    (best, best_k): (f32, usize),
    slopes: impl Fn() -> S,
) -> usize {
    let floor = PLAIN_SHARE * best;
    let eligible = |s: f32| s > 0.0 && s >= floor;
    let total: f32 = slopes().filter(|&s| eligible(s)).sum();
    let mut left = plain_hash(i) * total;
    for (k, s) in slopes().enumerate() {
        if eligible(s) {
            if left < s {
                return k;
            }
            left -= s;
        }
    }
    // Rounding left nothing drawn: the steepest.
    best_k
}

/// A uniform draw in [0, 1) for plain sample `i`, the same every step.
#[inline]
fn plain_hash(i: usize) -> f32 {
    crate::random::unit_f64(crate::random::hash3(PLAIN_SEED, 0, i as u64)) as f32
}

/// Hash stream of [`plain_draw`].
const PLAIN_SEED: u64 = 0x706c_6169_6e73;

/// [`sea_mask`] with an explicit scratch.
///
/// Method: the bodies of water are the connected components of the samples at or below sea
/// level, labelled by a union–find pass in index order (each body is named by its smallest
/// sample, which is also where the breadth-first search of the original formulation started),
/// then their areas are summed in index order. The area of a body whose sum lies so close to
/// `min_sea_area_km2` that the summation order could matter (within the rounding bound of an
/// n-term sum) is summed again in breadth-first order from its smallest sample, the order of
/// the reference formulation, so the mask is exactly that of a breadth-first search over the
/// bodies in index order. A graph with one-way edges gets that search directly.
///
/// Cost: O(n α(n)) sequential, cache-friendly (samples are stored along a space-filling curve);
/// the final write is parallel. The result does not depend on the thread count.
pub fn sea_mask_with(
    g: &ReliefGraph,
    elevation_km: &[f32],
    always_sea: &[bool],
    min_sea_area_km2: f64,
    out: &mut Vec<bool>,
    s: &mut SeaMaskScratch,
) {
    let n = g.len();
    out.clear();
    out.resize(n, false);
    if n == 0 {
        return;
    }
    let elev = &elevation_km[..elevation_km.len().min(n)];
    const CH: usize = 16384;
    let mut below_buf = std::mem::take(&mut s.below);
    below_buf.resize(n, false);
    below_buf.par_chunks_mut(CH).enumerate().for_each(|(c, b)| {
        for (k, b) in b.iter_mut().enumerate() {
            *b = match elev.get(c * CH + k) {
                Some(&z) => z.is_nan() || z <= 0.0,
                None => true,
            };
        }
    });
    let below_v = &below_buf[..];
    let below = |i: usize| -> bool { below_v[i] };
    let open_at = |i: usize| always_sea.get(i).copied().unwrap_or(false);
    if !g.is_symmetric() {
        sea_mask_bfs(g, &below, &open_at, min_sea_area_km2, out, s);
        s.below = below_buf;
        return;
    }
    s.parent.resize(n, 0);
    s.area.resize(n, 0.0);
    s.flags.resize(n, 0);
    let parent = &mut s.parent[..];
    // 1. The bodies: the connected sets of samples at or below sea level, each rooted at its
    //    smallest sample (see `join_components`).
    crate::geometry::union_find::join_components(&g.neighbor_start, &g.neighbors, &below, parent);
    // 2. Label every sample with its body and sum the bodies in index order; a body's
    //    smallest sample comes first. Links only ever point to smaller samples, so the sample
    //    `i` points to was labelled before it: its label is `i`'s root, one read away.
    let mut negative = false;
    for i in 0..n {
        if !below(i) {
            continue;
        }
        let p = parent[i] as usize;
        let r = if p == i { i } else { parent[p] as usize };
        parent[i] = r as u32;
        if r == i {
            s.area[r] = 0.0;
            s.flags[r] = 0;
        }
        let a = g.area_km2[i];
        negative |= a.is_nan() || a < 0.0;
        s.area[r] += a;
        if open_at(i) {
            s.flags[r] |= OPEN;
        }
    }
    // 3. Decide each open body. Two summation orders of m terms differ by at most
    //    2(m − 1)·u·Σ|a| (u = 2⁻⁵³); closer than that to the threshold, or with negative
    //    areas, the body is summed again in the reference (breadth-first) order.
    let margin = 4.0 * n as f64 * f64::EPSILON;
    for r in 0..n {
        if !below(r) || s.parent[r] as usize != r || s.flags[r] & OPEN == 0 {
            continue;
        }
        let a = s.area[r];
        let area = if negative || (a - min_sea_area_km2).abs() <= margin * a.abs() {
            bfs_body_area(g, &below, r, &mut s.queue, &mut s.seen)
        } else {
            a
        };
        if area >= min_sea_area_km2 {
            s.flags[r] |= SEA;
        }
    }
    // 4. Write the mask.
    let (parent, flags) = (&s.parent, &s.flags);
    out.par_chunks_mut(CH).enumerate().for_each(|(c, o)| {
        let base = c * CH;
        for (k, o) in o.iter_mut().enumerate() {
            let i = base + k;
            *o = below(i) && flags[parent[i] as usize] & SEA != 0;
        }
    });
    s.below = below_buf;
}

/// Area of the body of water containing `start`, summed in breadth-first order from `start`
/// (neighbours in CSR order), as the reference formulation sums it.
fn bfs_body_area(
    g: &ReliefGraph,
    below: &dyn Fn(usize) -> bool,
    start: usize,
    queue: &mut Vec<u32>,
    seen: &mut Vec<bool>,
) -> f64 {
    seen.resize(g.len(), false);
    queue.clear();
    queue.push(start as u32);
    seen[start] = true;
    let (mut head, mut area) = (0, 0.0f64);
    while head < queue.len() {
        let i = queue[head] as usize;
        head += 1;
        area += g.area_km2[i];
        for &j in g.neighbors_of(i) {
            let j = j as usize;
            if !seen[j] && below(j) {
                seen[j] = true;
                queue.push(j as u32);
            }
        }
    }
    for &i in queue.iter() {
        seen[i as usize] = false;
    }
    area
}

/// The reference formulation of [`sea_mask`]: one breadth-first search per body, bodies in
/// index order (used when the graph has one-way edges, where bodies are not components).
fn sea_mask_bfs(
    g: &ReliefGraph,
    below: &dyn Fn(usize) -> bool,
    open_at: &dyn Fn(usize) -> bool,
    min_sea_area_km2: f64,
    out: &mut [bool],
    s: &mut SeaMaskScratch,
) {
    let n = g.len();
    s.seen.clear();
    s.seen.resize(n, false);
    let (seen, body) = (&mut s.seen, &mut s.queue);
    for start in 0..n {
        if seen[start] || !below(start) {
            continue;
        }
        body.clear();
        body.push(start as u32);
        seen[start] = true;
        let (mut head, mut area, mut open) = (0, 0.0f64, false);
        while head < body.len() {
            let i = body[head] as usize;
            head += 1;
            area += g.area_km2[i];
            open |= open_at(i);
            for &j in g.neighbors_of(i) {
                let j = j as usize;
                if !seen[j] && below(j) {
                    seen[j] = true;
                    body.push(j as u32);
                }
            }
        }
        if open && area >= min_sea_area_km2 {
            for &i in body.iter() {
                out[i as usize] = true;
            }
        }
    }
    seen.iter_mut().for_each(|x| *x = false);
}
