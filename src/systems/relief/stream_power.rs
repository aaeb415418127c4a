//! Fluvial incision by the stream-power law, solved implicitly along the drainage network.
//!
//! Law (detachment-limited, Howard & Kerby 1983; Whipple & Tucker 1999, "Dynamics of the
//! stream-power river incision model", JGR 104(B8)), with an optional incision threshold
//! (Tucker & Bras 2000; Lague 2014, "The stream power river incision model: evidence, theory
//! and beyond", ESPL 39):
//!
//! ```text
//!   E = max(0, K · k_i · A^m · S^n − E_c)        [km/My = mm/yr]
//! ```
//!
//! with A the drainage area (km²), S = (h_i − h_r)/d_ir the slope to the receiver (m/m),
//! K the erodibility in km^(1−2m)/My (K = K_SI·10^(3+6m) for K_SI in m^(1−2m)/yr, see
//! [`StreamPowerParams::k`]), k_i an optional per-sample multiplier (lithology) and E_c the
//! threshold rate. Elevations are km; a river mouth's base level is sea level (0 km).
//!
//! Implicit scheme (Braun & Willett 2013, Geomorphology 180–181, eq. 21–24): visiting samples in
//! stack order (receiver first, so h_r is already at t+Δt),
//!
//! ```text
//!   n = 1:  h' = (h + F·h_r' + Δt·E_c) / (1 + F),   F = Δt·K·k_i·A^m / d
//!   n ≠ 1:  h' − h + Δt·(K·k_i·A^m·((h' − h_r')/d)^n − E_c) = 0   (Newton, bracketed)
//! ```
//!
//! which is unconditionally stable, so 2 My steps are fine, and never lowers a sample below its
//! receiver. Samples at or below their receiver (flats) and lake floors are not eroded; a
//! sample draining into a lake has the lake surface as base level, one draining to the sea
//! has sea level. Tectonic uplift
//! is applied by the caller before this pass.

use rayon::prelude::*;

use super::drainage::Drainage;
use super::graph::ReliefGraph;

/// Parameters of [`stream_power_erode`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamPowerParams {
    /// Erodibility K in km^(1−2m)/My, so that E [km/My] = K·A\[km²\]^m·S^n. Conversion from
    /// SI (m^(1−2m)/yr): K = K_SI·10^(3+6m); for m = 0.5, K_SI = 1e−6/yr ↔ K = 1/My.
    pub k: f64,
    /// Area exponent m (dimensionless).
    pub m: f64,
    /// Slope exponent n (dimensionless, > 0).
    pub n: f64,
    /// Incision threshold E_c, km/My (= mm/yr); 0 disables it.
    pub threshold_km_per_my: f64,
    /// Resolution correction: drainage areas are multiplied by
    /// (`reference_spacing_km` / mean spacing)^`spacing_exponent` before A^m (see NOTES.md,
    /// "Resolution independence"). `spacing_exponent` = 0 disables it.
    pub reference_spacing_km: f64,
    /// See `reference_spacing_km`.
    pub spacing_exponent: f64,
}

impl Default for StreamPowerParams {
    fn default() -> Self {
        // Calibrated with isostasy in the loop (NOTES.md, "Calibration").
        Self {
            k: 0.5,
            m: 0.5,
            n: 1.0,
            threshold_km_per_my: 0.3,
            reference_spacing_km: 50.0,
            spacing_exponent: 1.0,
        }
    }
}

impl StreamPowerParams {
    /// Multiplier applied to drainage areas for graph `g` (1 when the correction is off).
    pub fn area_scale(&self, g: &ReliefGraph) -> f64 {
        if self.spacing_exponent == 0.0
            || g.mean_spacing_km <= 0.0
            || self.reference_spacing_km <= 0.0
        {
            1.0
        } else {
            (self.reference_spacing_km / g.mean_spacing_km).powf(self.spacing_exponent)
        }
    }
}

/// Scratch for [`stream_power_erode`].
#[derive(Clone, Debug, Default)]
pub struct StreamPowerScratch {
    coef: Vec<f64>,
}

/// Erodes land samples of `elevation_km` in place over `dt_my` My along `drainage` (computed
/// on the same surface). Writes the eroded thickness (km, ≥ 0) of every sample to `eroded_km`
/// (0 for ocean and untouched samples) and returns the eroded volume Σ e_i·a_i in km³.
/// `erodibility` is an optional per-sample multiplier of K (≥ 0; missing = 1).
#[allow(clippy::too_many_arguments)]
pub fn stream_power_erode(
    g: &ReliefGraph,
    drainage: &Drainage,
    elevation_km: &mut [f32],
    eroded_km: &mut [f32],
    erodibility: Option<&[f32]>,
    p: &StreamPowerParams,
    dt_my: f64,
    scratch: &mut StreamPowerScratch,
) -> f64 {
    stream_power_erode_to(
        g,
        drainage,
        &drainage.ocean,
        elevation_km,
        eroded_km,
        erodibility,
        p,
        dt_my,
        scratch,
    )
}

/// [`stream_power_erode`] on a network built on an earlier step, with `sea` the sea now (see
/// [`super::coast::refresh_sea`]): a receiver now at sea is the base level 0; one the network
/// put at sea that rose above it since is its own height. Without the first, land that sank
/// below sea level since the network was built (the isostasy, a falling margin) would take the
/// rivers draining to it below the sea: on the second step of seed 1 at 100k the land fraction
/// fell from 0.237 to 0.205.
#[allow(clippy::too_many_arguments)]
pub fn stream_power_erode_to(
    g: &ReliefGraph,
    drainage: &Drainage,
    sea: &[bool],
    elevation_km: &mut [f32],
    eroded_km: &mut [f32],
    erodibility: Option<&[f32]>,
    p: &StreamPowerParams,
    dt_my: f64,
    scratch: &mut StreamPowerScratch,
) -> f64 {
    let n = g.len();
    eroded_km.iter_mut().for_each(|e| *e = 0.0);
    if elevation_km.len() < n
        || eroded_km.len() < n
        || sea.len() < n
        || drainage.receiver.len() < n
        || !(dt_my > 0.0)
        || !(p.k > 0.0)
        || !(p.n > 0.0)
    {
        return 0.0;
    }
    let area_scale = p.area_scale(g);
    // Per-sample coefficient Δt·K·k_i·A^m / d^n (parallel, independent per sample).
    scratch.coef.resize(n, 0.0);
    let (m, nexp, k) = (p.m, p.n, p.k);
    scratch
        .coef
        .par_iter_mut()
        .enumerate()
        .with_min_len(8192)
        .for_each(|(i, c)| {
            *c = 0.0;
            if drainage.ocean[i] {
                return;
            }
            let d = drainage.receiver_km[i] as f64;
            if drainage.receiver[i] as usize == i || d <= 0.0 {
                return;
            }
            let ki = erodibility
                .and_then(|e| e.get(i).copied())
                .filter(|x| x.is_finite())
                .unwrap_or(1.0)
                .max(0.0) as f64;
            let a = drainage.area_km2[i] * area_scale;
            let am = if m == 0.5 { a.sqrt() } else { a.powf(m) };
            let dn = if nexp == 1.0 { d } else { d.powf(nexp) };
            *c = dt_my * k * ki * am / dn;
        });
    let ec = p.threshold_km_per_my.max(0.0) * dt_my;
    let mut volume = 0.0f64;
    for &i in &drainage.stack {
        let i = i as usize;
        let f = scratch.coef[i];
        if f <= 0.0 {
            continue;
        }
        // Lake floors are not incised; a river entering a lake erodes down to the lake
        // surface, not its floor (otherwise deep closed holes pull their rims down).
        if drainage.is_lake(i) {
            continue;
        }
        let r = drainage.receiver[i] as usize;
        let hr = if sea[r] {
            0.0
        } else if drainage.ocean[r] {
            // Put at sea by the network, risen above sea level since.
            (elevation_km[r] as f64).max(0.0)
        } else if drainage.is_lake(r) {
            drainage.water_level_km[r] as f64
        } else {
            elevation_km[r] as f64
        };
        let h = elevation_km[i] as f64;
        if !h.is_finite() || !hr.is_finite() || h <= hr {
            continue;
        }
        let d = drainage.receiver_km[i] as f64;
        let new_h = if nexp == 1.0 {
            // Below the threshold at the current slope: no incision.
            if f * (h - hr) <= ec {
                continue;
            }
            ((h + f * hr + ec) / (1.0 + f)).clamp(hr, h)
        } else {
            // g(x) = x − h + f·(x − h_r)^n − ec, with f = Δt·K·A^m/d^n; root in (h_r, h).
            let gfun = |x: f64| x - h + f * (x - hr).max(0.0).powf(nexp) - ec;
            if gfun(h) <= 0.0 {
                continue;
            }
            let (mut lo, mut hi) = (hr, h);
            let mut x = h;
            for _ in 0..50 {
                let gx = gfun(x);
                if gx > 0.0 {
                    hi = x;
                } else {
                    lo = x;
                }
                let dg = 1.0 + f * nexp * (x - hr).max(1e-12).powf(nexp - 1.0);
                let mut nx = x - gx / dg;
                if !(nx > lo && nx < hi) {
                    nx = 0.5 * (lo + hi);
                }
                if (nx - x).abs() <= 1e-10 * (1.0 + x.abs()) {
                    x = nx;
                    break;
                }
                x = nx;
            }
            let _ = d;
            x.clamp(hr, h)
        };
        let e = h - new_h;
        if e > 0.0 {
            elevation_km[i] = new_h as f32;
            // Record what was actually removed from the stored f32 surface.
            let stored = (h - elevation_km[i] as f64) as f32;
            eroded_km[i] = stored;
            volume += stored as f64 * g.area_km2[i];
        }
    }
    volume
}

/// Steady-state slope of the stream-power law for uplift rate `u` (km/My): the slope at which
/// erosion balances uplift, S = ((U + E_c)/(K·(s·A)^m))^(1/n) (m/m), A in km², with
/// s = [`StreamPowerParams::area_scale`] of the graph (pass 1.0 when the correction is off).
pub fn steady_state_slope(
    p: &StreamPowerParams,
    u_km_per_my: f64,
    area_km2: f64,
    area_scale: f64,
) -> f64 {
    ((u_km_per_my + p.threshold_km_per_my.max(0.0)) / (p.k * (area_scale * area_km2).powf(p.m)))
        .powf(1.0 / p.n)
}
