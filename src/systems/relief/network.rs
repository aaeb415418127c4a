//! The drainage network of a given crust, for the outputs (maps, GeoJSON, GeoTIFF, viewer): the
//! network itself ([`network_of`], as [`build_drainage`](super::build_drainage) makes it every
//! step), the basin of every sample ([`basin_outlets`]) and the rivers cut into reaches
//! ([`river_reaches`]).
//!
//! A *channel* is a land sample whose drainage area is at least a threshold (km²); a *river
//! sample* is a channel that is not under a lake. Flow only grows downstream, so the receiver of
//! a channel is a channel, a lake or the sea: the channels form a forest whose roots are in the
//! sea, in lakes or in endorheic sinks.
//!
//! A *reach* runs from a source, a confluence or a lake outlet down to the next confluence, lake,
//! sink or the sea. It starts at every river sample that has no channel donor (a source), two or
//! more (a confluence), or only a lake (an outlet); its last point is the sample where it ends
//! (a sea sample, a lake sample, a sink, or the first sample of the reach below a confluence).
//! Strahler orders (Strahler 1957) are counted over the channels: a source has order 1, and
//! where two or more channels of the highest order meet, the order goes up by one.
//!
//! Invariants (tested): every sample's basin is its receiver's; every reach has at least two
//! points, each the receiver of the one before; a reach that ends at a confluence ends where its
//! downstream reach starts.

use super::drainage::{Drainage, sea_mask};
use super::graph::ReliefGraph;
use crate::geometry::SphereMesh;
use crate::resources::{Crust, CrustType};

/// The least drainage area of a mapped river, km²: the main rivers of a continent show on a
/// 2048-pixel map (the Rhine drains 185,000 km², the Thames 13,000). On a coarse planet the
/// threshold is at least [`RIVER_MIN_SAMPLES`] samples' area ([`river_threshold_km2`]).
pub const RIVER_MIN_AREA_KM2: f64 = 50_000.0;

/// On a coarse planet, a mapped river drains at least this many samples' mean area, so that
/// not every land sample is a river.
pub const RIVER_MIN_SAMPLES: f64 = 8.0;

/// The drainage-area threshold of mapped rivers on a planet of `samples` samples covering
/// `total_area_km2`: [`RIVER_MIN_AREA_KM2`], or [`RIVER_MIN_SAMPLES`] mean sample areas when
/// that is more.
pub fn river_threshold_km2(total_area_km2: f64, samples: usize) -> f64 {
    let per_sample = total_area_km2 / samples.max(1) as f64;
    RIVER_MIN_AREA_KM2.max(RIVER_MIN_SAMPLES * per_sample)
}

/// The sample graph of `mesh` (what every relief pass works on).
pub fn relief_graph(mesh: &SphereMesh) -> ReliefGraph {
    ReliefGraph::from_shared(
        &mesh.positions,
        &mesh.neighbor_start,
        &mesh.neighbors,
        Some(&mesh.triangles),
        Some(&mesh.area_km2),
        mesh.radius_km,
    )
}

/// [`relief_graph`] without the cotangent weights (every edge gets
/// [`super::graph::LATTICE_WEIGHT`]), for what reads only the edges' lengths and the samples'
/// areas: the drainage network, the climate's rain and the river reaches (exports and maps).
/// The weights are a serial pass over the triangles, about 100 ms at 500,000 samples; the
/// hillslope diffusion and the isostasy's flexure need them ([`relief_graph`]).
pub fn drainage_graph(mesh: &SphereMesh) -> ReliefGraph {
    ReliefGraph::from_shared(
        &mesh.positions,
        &mesh.neighbor_start,
        &mesh.neighbors,
        None,
        Some(&mesh.area_km2),
        mesh.radius_km,
    )
}

/// What decides the sea and the lakes of a drainage network, as in the simulation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NetworkOptions {
    /// Smallest body of water that is sea (parameter `rivers.min_sea_area_km2`).
    pub min_sea_area_km2: f64,
    /// Water balance of closed lakes (see [`Drainage::lake_area_ratio`]).
    pub lake_area_ratio: Option<f64>,
    /// The rain of the phenomenon `climate` ([`super::climate`]); `None`: uniform rain.
    pub climate: Option<super::climate::ClimateParams>,
}

impl NetworkOptions {
    /// The options the simulation uses with `params`, the climate on (its default; see
    /// [`Self::with_climate`]).
    pub fn of(params: &crate::resources::Params) -> Self {
        Self {
            min_sea_area_km2: params.rivers.min_sea_area_km2,
            lake_area_ratio: super::lake_area_ratio(params),
            climate: Some(super::climate_params(params)),
        }
    }

    /// The same with the climate's rain when `climate_on` (the phenomenon `climate` is on in
    /// the run), uniform rain otherwise.
    pub fn with_climate(self, climate_on: bool) -> Self {
        Self {
            climate: self.climate.filter(|_| climate_on),
            ..self
        }
    }
}

/// The rain of `opts.climate` over `crust` on graph `g` (`positions`: the graph's unit
/// positions); empty with uniform rain.
pub fn rain_of(
    g: &ReliefGraph,
    positions: &[glam::DVec3],
    crust: &Crust,
    opts: NetworkOptions,
) -> Vec<f32> {
    let mut rain = Vec::new();
    if let Some(c) = opts.climate {
        super::climate::precipitation(
            g,
            positions,
            &crust.elevation_km,
            &c,
            &mut rain,
            &mut super::climate::ClimateScratch::default(),
        );
    }
    rain
}

/// The drainage network of `crust` on graph `g`: the sea is the oceanic bodies of water of at
/// least `opts.min_sea_area_km2`, the lakes balanced as `opts` says, drainage areas weighted by
/// `rain` (relative, one value per sample; `None` or empty: uniform), as in the simulation. Give
/// it the resampled crust (world frame, reference mesh) to map it.
pub fn network_of(
    g: &ReliefGraph,
    crust: &Crust,
    opts: NetworkOptions,
    rain: Option<&[f32]>,
) -> Drainage {
    let oceanic: Vec<bool> = crust
        .crust_type
        .iter()
        .map(|&t| t == CrustType::Oceanic)
        .collect();
    let mut ocean = Vec::new();
    sea_mask(
        g,
        &crust.elevation_km,
        &oceanic,
        opts.min_sea_area_km2,
        &mut ocean,
    );
    let mut d = Drainage::new();
    d.lake_area_ratio = opts.lake_area_ratio;
    let rain = rain.filter(|r| r.len() == g.len());
    d.compute(g, &crust.elevation_km, &ocean, rain);
    d
}

/// The outlet of every sample: the sea sample its water reaches, or the endorheic sink it
/// ends in (a sample's drainage basin is the set of samples with the same outlet). A sea
/// sample is its own outlet; every sample's outlet is its receiver's.
pub fn basin_outlets(d: &Drainage) -> Vec<u32> {
    let n = d.receiver.len();
    let mut out: Vec<u32> = (0..n as u32).collect();
    // Receivers come before donors in the stack.
    for &i in &d.stack {
        let i = i as usize;
        if let Some(&r) = d.receiver.get(i) {
            let r = r as usize;
            if r != i && r < n {
                out[i] = out[r];
            }
        }
    }
    out
}

/// Where a reach ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ReachEnd {
    /// In the sea (the last point is a sea sample).
    Sea,
    /// In a lake (the last point is under a lake; the lake's outlet starts another reach).
    Lake,
    /// At an endorheic sink (the lowest point of a basin without a route to the sea).
    Sink,
    /// Where it meets a river at least as large (the last point starts the downstream reach).
    Confluence,
}

impl ReachEnd {
    /// The name written in the outputs: `sea`, `lake`, `sink`, `confluence`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Sea => "sea",
            Self::Lake => "lake",
            Self::Sink => "sink",
            Self::Confluence => "confluence",
        }
    }
}

/// One river reach.
#[derive(Clone, Debug, PartialEq)]
pub struct Reach {
    /// The samples along it, downstream; each is the receiver of the one before (at least two).
    pub samples: Vec<u32>,
    /// Where it ends.
    pub end: ReachEnd,
    /// Drainage area where it ends (at its last river sample, before the sea, lake or
    /// confluence), km².
    pub area_km2: f64,
    /// Strahler order.
    pub strahler: u32,
    /// Rank by drainage area among all reaches (1: the largest).
    pub rank: u32,
    /// The reach its water flows on in (below a confluence, or out of the lake), if any.
    pub downstream: Option<usize>,
    /// The outlet of its basin (see [`basin_outlets`]).
    pub outlet: u32,
    /// Length along the receivers, km.
    pub length_km: f64,
}

/// The rivers of `d` whose drainage area is at least `min_area_km2`, cut into reaches (see the
/// module doc). Reaches are listed by their first sample's position in the stack (outlets
/// first), so the order does not depend on the thread count.
pub fn river_reaches(d: &Drainage, min_area_km2: f64) -> Vec<Reach> {
    let n = d.receiver.len();
    if d.ocean.len() != n || d.area_km2.len() != n || d.water_level_km.len() != n {
        return Vec::new();
    }
    let channel = |i: usize| !d.ocean[i] && d.area_km2[i] >= min_area_km2;
    let lake = |i: usize| d.is_lake(i);
    let sink = |i: usize| !d.ocean[i] && d.receiver[i] as usize == i;
    // Channel donors and Strahler orders, donors before receivers.
    let mut donors = vec![0u32; n];
    let mut lake_donors = vec![0u32; n];
    let mut best = vec![(0u32, 0u32); n]; // (highest donor order, how many have it)
    let mut order = vec![0u32; n];
    for &i in d.stack.iter().rev() {
        let i = i as usize;
        if !channel(i) {
            continue;
        }
        let (o, k) = best[i];
        order[i] = match (o, k) {
            (0, _) => 1,
            (o, k) if k >= 2 => o + 1,
            (o, _) => o,
        };
        let r = d.receiver[i] as usize;
        if r != i && channel(r) {
            donors[r] += 1;
            if lake(i) {
                lake_donors[r] += 1;
            }
            let b = &mut best[r];
            if order[i] > b.0 {
                *b = (order[i], 1);
            } else if order[i] == b.0 {
                b.1 += 1;
            }
        }
    }
    let river = |i: usize| channel(i) && !lake(i);
    let starts = |i: usize| river(i) && (donors[i] != 1 || lake_donors[i] == 1) && !sink(i);
    let mut reach_at = vec![u32::MAX; n];
    let mut reaches: Vec<Reach> = Vec::new();
    let outlets = basin_outlets(d);
    for &s in &d.stack {
        let s = s as usize;
        if !starts(s) {
            continue;
        }
        let mut samples = vec![s as u32];
        let mut length_km = 0.0;
        let mut cur = s;
        let end = loop {
            let r = d.receiver[cur] as usize;
            length_km += f64::from(d.receiver_km[cur]);
            samples.push(r as u32);
            if d.ocean[r] {
                break ReachEnd::Sea;
            }
            if lake(r) {
                break ReachEnd::Lake;
            }
            if sink(r) {
                break ReachEnd::Sink;
            }
            if starts(r) || samples.len() > n {
                break ReachEnd::Confluence;
            }
            cur = r;
        };
        reach_at[s] = reaches.len() as u32;
        reaches.push(Reach {
            area_km2: d.area_km2[cur],
            strahler: order[s],
            rank: 0,
            downstream: None,
            outlet: outlets[s],
            length_km,
            end,
            samples,
        });
    }
    for reach in &mut reaches {
        let Some(&last) = reach.samples.last() else {
            continue;
        };
        let mut x = last as usize;
        let below = match reach.end {
            ReachEnd::Confluence => Some(x),
            ReachEnd::Lake => {
                // Through the lake to its outlet.
                let mut steps = 0;
                while lake(x) && steps <= n {
                    x = d.receiver[x] as usize;
                    steps += 1;
                }
                starts(x).then_some(x)
            }
            ReachEnd::Sea | ReachEnd::Sink => None,
        };
        reach.downstream = below
            .map(|x| reach_at[x])
            .filter(|&r| r != u32::MAX)
            .map(|r| r as usize);
    }
    let mut by_area: Vec<usize> = (0..reaches.len()).collect();
    by_area.sort_by(|&a, &b| {
        reaches[b]
            .area_km2
            .total_cmp(&reaches[a].area_km2)
            .then(a.cmp(&b))
    });
    for (rank, k) in by_area.into_iter().enumerate() {
        reaches[k].rank = rank as u32 + 1;
    }
    reaches
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A planet with two continents of smooth hills (a cap around +x, one around −x), ocean
    /// elsewhere, and a closed depression on the first.
    fn planet() -> (SphereMesh, Crust) {
        let mesh = SphereMesh::fibonacci(20_000, 0.5, 3, 6371.0).expect("mesh");
        let mut c = Crust::with_len(mesh.len());
        for (i, p) in mesh.positions.iter().enumerate() {
            let land = p.x.abs() > 0.45;
            if land {
                c.crust_type[i] = CrustType::Continental;
                let bumps = 0.3 * ((7.0 * p.y).sin() * (5.0 * p.z).cos()) as f32;
                let pit = 0.9 * (-((p.y - 0.2).powi(2) + (p.z - 0.1).powi(2)) / 0.004).exp() as f32;
                c.elevation_km[i] = 2.5 * (p.x.abs() - 0.45) as f32 + 0.05 + bumps.abs() - pit;
            } else {
                c.elevation_km[i] = -4.0;
            }
        }
        (mesh, c)
    }

    #[test]
    fn basins_follow_receivers_and_reaches_chain_to_the_sea() {
        let (mesh, crust) = planet();
        let g = relief_graph(&mesh);
        let d = network_of(
            &g,
            &crust,
            NetworkOptions {
                min_sea_area_km2: 250_000.0,
                lake_area_ratio: None,
                climate: None,
            },
            None,
        );
        let outlets = basin_outlets(&d);
        for i in 0..mesh.len() {
            let r = d.receiver[i] as usize;
            assert_eq!(outlets[i], outlets[r], "sample {i} and its receiver {r}");
            let o = outlets[i] as usize;
            assert!(d.ocean[o] || d.sinks.contains(&(o as u32)), "outlet {o}");
        }
        assert!(d.lake_sample_count > 0, "the depression holds a lake");
        let t = river_threshold_km2(g.total_area_km2(), mesh.len());
        let reaches = river_reaches(&d, t);
        assert!(reaches.len() > 10, "{} reaches", reaches.len());
        let mut ends = std::collections::HashMap::new();
        for (k, r) in reaches.iter().enumerate() {
            assert!(r.samples.len() >= 2, "reach {k}");
            for w in r.samples.windows(2) {
                assert_eq!(d.receiver[w[0] as usize], w[1], "reach {k}");
            }
            *ends.entry(r.end).or_insert(0) += 1;
            let last = *r.samples.last().unwrap() as usize;
            match r.end {
                ReachEnd::Sea => assert!(d.ocean[last]),
                ReachEnd::Lake => assert!(d.is_lake(last)),
                ReachEnd::Sink => assert!(d.sinks.contains(&(last as u32))),
                ReachEnd::Confluence => {
                    let below = &reaches[r.downstream.expect("a confluence leads on")];
                    assert_eq!(below.samples[0] as usize, last);
                    assert!(below.strahler >= r.strahler);
                    assert!(below.area_km2 > r.area_km2);
                }
            }
            // Following the reaches downstream ends in the sea, a lake or a sink.
            let (mut at, mut hops) = (k, 0);
            while let Some(next) = reaches[at].downstream {
                at = next;
                hops += 1;
                assert!(hops <= reaches.len(), "a cycle of reaches");
            }
            assert_ne!(reaches[at].end, ReachEnd::Confluence);
            assert!(r.area_km2 >= t);
        }
        assert!(
            ends.get(&ReachEnd::Sea).copied().unwrap_or(0) > 2,
            "{ends:?}"
        );
        assert!(
            ends.get(&ReachEnd::Confluence).copied().unwrap_or(0) > 2,
            "{ends:?}"
        );
        assert!(reaches.iter().any(|r| r.strahler >= 2));
        let mut ranks: Vec<u32> = reaches.iter().map(|r| r.rank).collect();
        ranks.sort_unstable();
        assert_eq!(ranks, (1..=reaches.len() as u32).collect::<Vec<_>>());
    }
}
