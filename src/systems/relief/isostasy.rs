//! Isostasy: continental surface elevation from crust thickness (Airy, with a regional
//! response standing in for flexure), and ocean depth from sea-floor age (plate cooling) with
//! the isostatic effect of the sediment load.
//!
//! **Airy** (Airy 1855; Turcotte & Schubert 2014, *Geodynamics* §2.2): a column of crust of
//! thickness T and density ρ_c floating on mantle ρ_m, relative to a reference column T₀ whose
//! surface stands at h₀:
//!
//! ```text
//!   dry:       h = h₀ + (T − T₀)·(1 − ρ_c/ρ_m)                  (h ≥ 0)
//!   submerged: h = [ρ_m·h₀ + (T − T₀)·(ρ_m − ρ_c)] / (ρ_m − ρ_w)  (h < 0, water load)
//! ```
//!
//! With ρ_c = 2.8, ρ_m = 3.3 g/cm³, 1 km of extra crust raises the surface by 0.1515 km.
//!
//! **Regional response** (Vening Meinesz regional compensation, Watts 2001, *Isostasy and
//! Flexure of the Lithosphere* §2–3): the root r = (T − T₀)·ρ_c/ρ_m that local Airy isostasy
//! would give (0 under oceanic crust) is smoothed with a Gaussian-like kernel into the plate
//! deflection w = G∗r, which is subtracted everywhere: continents h = h₀ + (T − T₀) − w,
//! sea floor (age–depth) − w. A narrow range is thus partly held up by the plate around it
//! and drags its surroundings (including the sea floor next to it: a flexural moat) down,
//! while at long wavelengths the result is exactly Airy (G conserves Σ a·r). The
//! kernel width comes from the elastic thickness T_e: flexural rigidity D = E·T_e³/(12(1−ν²)),
//! flexural parameter α = (4D/((ρ_m − ρ_c)·g))^¼, and σ = 0.83·α matches the half-power
//! wavelength of the thin-plate response 1/(1 + (kα)⁴/4). G is applied as k
//! conservative heat-equation passes on the graph (k·λ = σ²/2), or, when that would take many
//! passes, on a coarser Fibonacci mesh (restrict with the transpose of the barycentric
//! interpolation, smooth, interpolate back).
//!
//! **Ocean depth** (km below sea level, age t in My): GDH1, Stein & Stein 1992, *Nature* 359:
//! d = 2.6 + 0.365·√t (t < 20), 5.651 − 2.473·e^(−0.0278·t) otherwise; Parsons & Sclater 1977,
//! *JGR* 82: d = 2.5 + 0.35·√t (t < 70), 6.4 − 3.2·e^(−t/62.8) otherwise. Sediment of thickness
//! s raises the sea floor by s·(ρ_m − ρ_s)/(ρ_m − ρ_w) (loaded-basement correction, e.g.
//! Sclater & Christie 1980).

use rayon::prelude::*;

use super::graph::ReliefGraph;
use crate::gpu::isostasy::{AgeDepthSamples, IsostasyConstants};
use crate::resources::CrustType;

/// Densities (g/cm³), reference column and elastic plate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IsostasyParams {
    /// Crust density ρ_c, g/cm³.
    pub rho_crust: f64,
    /// Mantle density ρ_m, g/cm³.
    pub rho_mantle: f64,
    /// Sea-water density ρ_w, g/cm³.
    pub rho_water: f64,
    /// Compacted sediment density ρ_s, g/cm³ (for sediment on oceanic crust).
    pub rho_sediment: f64,
    /// Reference continental thickness T₀, km.
    pub ref_thickness_km: f64,
    /// Surface elevation of the reference column, h₀, km (≥ 0).
    pub ref_elevation_km: f64,
    /// Effective elastic thickness T_e, km (0 = local Airy).
    pub elastic_thickness_km: f64,
    /// Young's modulus E, GPa.
    pub young_modulus_gpa: f64,
    /// Poisson's ratio ν.
    pub poisson: f64,
    /// Gravity, m/s².
    pub gravity: f64,
    /// Most the plate holds a sample above (or pulls it below) its local Airy level, km: the
    /// deflection is kept within this of the sample's own root. The smoothed root stands in for
    /// flexure at the scale of the elastic plate; at the scale of one sample, where erosion,
    /// lakes and thin slivers of crust make contrasts no real plate carries, unbounded support
    /// lets a one-sample load stand tens of kilometres high over a moat as deep.
    pub max_support_km: f64,
}

impl Default for IsostasyParams {
    fn default() -> Self {
        Self {
            rho_crust: 2.8,
            rho_mantle: 3.3,
            rho_water: 1.03,
            rho_sediment: 2.5,
            ref_thickness_km: 35.0,
            ref_elevation_km: 0.4,
            elastic_thickness_km: 25.0,
            young_modulus_gpa: 100.0,
            poisson: 0.25,
            gravity: 9.81,
            max_support_km: f64::INFINITY,
        }
    }
}

impl IsostasyParams {
    /// Surface rise per km of crust added on dry land, 1 − ρ_c/ρ_m (0.1515 by default).
    pub fn dry_gain(&self) -> f64 {
        1.0 - self.rho_crust / self.rho_mantle
    }

    /// Surface rise per km of crust added under water, (ρ_m − ρ_c)/(ρ_m − ρ_w) (0.220).
    pub fn wet_gain(&self) -> f64 {
        (self.rho_mantle - self.rho_crust) / (self.rho_mantle - self.rho_water)
    }

    /// Sea-floor rise per km of sediment on oceanic crust, (ρ_m − ρ_s)/(ρ_m − ρ_w) (0.352).
    pub fn sediment_gain(&self) -> f64 {
        (self.rho_mantle - self.rho_sediment) / (self.rho_mantle - self.rho_water)
    }

    /// Flexural parameter α, km (≈ 103 km for T_e = 25 km, E = 100 GPa, ν = 0.25).
    pub fn flexural_parameter_km(&self) -> f64 {
        let te = self.elastic_thickness_km.max(0.0) * 1e3;
        let d = self.young_modulus_gpa * 1e9 * te.powi(3) / (12.0 * (1.0 - self.poisson.powi(2)));
        let drho = (self.rho_mantle - self.rho_crust).max(1e-6) * 1e3;
        (4.0 * d / (drho * self.gravity)).powf(0.25) / 1e3
    }

    /// Width σ (km) of the Gaussian standing in for the flexural response, 0.83·α.
    pub fn regional_sigma_km(&self) -> f64 {
        0.832 * self.flexural_parameter_km()
    }

    /// The constants of the per-sample combine ([`isostasy_cpu`] and the GPU kernel), with
    /// oceanic crust `oceanic_thickness_km` thick (what lies above it is load).
    pub fn constants(&self, oceanic_thickness_km: f64) -> IsostasyConstants {
        IsostasyConstants {
            ref_thickness_km: self.ref_thickness_km,
            ref_elevation_km: self.ref_elevation_km,
            root_ratio: self.rho_crust / self.rho_mantle,
            rho_mantle: self.rho_mantle,
            rho_water: self.rho_water,
            max_support_km: self.max_support_km,
            oceanic_thickness_km,
            sediment_gain: self.sediment_gain(),
            max_oceanic_load_km: f64::INFINITY,
            max_continental_km: f64::INFINITY,
        }
    }
}

/// Local Airy surface elevation (km) of continental crust `thickness_km` thick.
pub fn airy_elevation(thickness_km: f64, p: &IsostasyParams) -> f64 {
    let dry = p.ref_elevation_km + (thickness_km - p.ref_thickness_km) * p.dry_gain();
    submerge(dry, p)
}

/// Applies the water load to a "dry" elevation: unchanged if ≥ 0, else × ρ_m/(ρ_m − ρ_w).
#[inline]
fn submerge(dry_km: f64, p: &IsostasyParams) -> f64 {
    if dry_km >= 0.0 {
        dry_km
    } else {
        dry_km * p.rho_mantle / (p.rho_mantle - p.rho_water)
    }
}

/// Inverse of [`airy_elevation`]: the crust thickness (km) that stands at `elevation_km`.
pub fn airy_thickness(elevation_km: f64, p: &IsostasyParams) -> f64 {
    let dry = if elevation_km >= 0.0 {
        elevation_km
    } else {
        elevation_km * (p.rho_mantle - p.rho_water) / p.rho_mantle
    };
    p.ref_thickness_km + (dry - p.ref_elevation_km) / p.dry_gain()
}

/// Which plate-cooling law gives ocean depth from age.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum AgeDepthLaw {
    /// Stein & Stein 1992 (GDH1).
    #[default]
    Gdh1,
    /// Parsons & Sclater 1977.
    ParsonsSclater,
}

impl AgeDepthLaw {
    /// The law the parameters choose (`isostasy.parsons_sclater`).
    pub fn of(params: &crate::resources::Params) -> Self {
        if params.isostasy.parsons_sclater {
            AgeDepthLaw::ParsonsSclater
        } else {
            AgeDepthLaw::Gdh1
        }
    }
}

/// The sea-floor elevation (km, negative) of bare oceanic crust `age_my` old under the law and
/// ridge offset the parameters choose: what isostasy gives new ocean floor without sediment.
pub fn ocean_floor_km(age_my: f64, params: &crate::resources::Params) -> f64 {
    -ocean_depth_km(
        age_my,
        AgeDepthLaw::of(params),
        params.isostasy.ridge_depth_offset_km,
    )
}

/// Ocean depth (km, positive down) of sea floor `age_my` old, plus `ridge_offset_km` (use it to
/// move the ridge to the observed −2.7…−3.0 km; 0 keeps the published law).
pub fn ocean_depth_km(age_my: f64, law: AgeDepthLaw, ridge_offset_km: f64) -> f64 {
    let t = if age_my.is_finite() {
        age_my.max(0.0)
    } else {
        0.0
    };
    let d = match law {
        AgeDepthLaw::Gdh1 => {
            if t < 20.0 {
                2.6 + 0.365 * t.sqrt()
            } else {
                5.651 - 2.473 * (-0.0278 * t).exp()
            }
        }
        AgeDepthLaw::ParsonsSclater => {
            if t < 70.0 {
                2.5 + 0.35 * t.sqrt()
            } else {
                6.4 - 3.2 * (-t / 62.8).exp()
            }
        }
    };
    d + ridge_offset_km
}

/// Tabulated age–depth law (0.05 My steps to 400 My, linear interpolation; error < 0.1 m),
/// about 10× faster than evaluating exp/sqrt per sample.
#[derive(Clone, Debug)]
pub struct AgeDepthTable {
    depth: Vec<f64>,
}

impl AgeDepthTable {
    /// Age step of the table, My.
    pub const STEP: f64 = 0.05;
    /// Ages are clamped to this, My.
    pub const MAX_AGE: f64 = 400.0;

    /// Table of [`ocean_depth_km`] for `law` and `ridge_offset_km`.
    pub fn new(law: AgeDepthLaw, ridge_offset_km: f64) -> Self {
        let n = (Self::MAX_AGE / Self::STEP) as usize + 2;
        Self {
            depth: (0..n)
                .map(|k| ocean_depth_km(k as f64 * Self::STEP, law, ridge_offset_km))
                .collect(),
        }
    }

    /// Depth (km, positive down) at `age_my` (clamped to 0..400 My; NaN → 0).
    #[inline]
    pub fn depth_km(&self, age_my: f64) -> f64 {
        let t = if age_my.is_finite() {
            age_my.clamp(0.0, Self::MAX_AGE)
        } else {
            0.0
        };
        let x = t / Self::STEP;
        let k = (x as usize).min(self.depth.len() - 2);
        let f = x - k as f64;
        self.depth[k] * (1.0 - f) + self.depth[k + 1] * f
    }

    /// The tabulated depths, their step and the clamp age (what the GPU kernel interpolates).
    pub fn samples(&self) -> AgeDepthSamples<'_> {
        AgeDepthSamples {
            depth_km: &self.depth,
            step_my: Self::STEP,
            max_age_my: Self::MAX_AGE,
        }
    }
}

/// Sea-floor elevation (km, negative) for age and sediment thickness `sediment_km` on it.
pub fn ocean_elevation_km(
    age_my: f64,
    sediment_km: f64,
    law: AgeDepthLaw,
    ridge_offset_km: f64,
    p: &IsostasyParams,
) -> f64 {
    let s = if sediment_km.is_finite() {
        sediment_km.max(0.0)
    } else {
        0.0
    };
    -ocean_depth_km(age_my, law, ridge_offset_km) + s * p.sediment_gain()
}

/// A coarser Fibonacci mesh with interpolation weights, used to apply the regional kernel
/// when it spans many fine spacings (a two-level scheme: restrict, smooth, interpolate).
#[derive(Clone, Debug, Default)]
struct CoarseLevel {
    sigma_km: f64,
    n_fine: usize,
    c_start: std::sync::Arc<[u32]>,
    c_nbrs: std::sync::Arc<[u32]>,
    /// Per fine sample: the coarse triangle's corners and barycentric weights.
    p_idx: Vec<[u32; 3]>,
    p_w: Vec<[f32; 3]>,
    /// Transpose (restriction): per coarse node, (fine sample, weight × fine area); and the
    /// interpolation weights above are divided by the smoothed area G∗a, so that the result is
    /// the area-weighted average G∗(a·r)/G∗(a).
    r_start: Vec<u32>,
    r_fine: Vec<u32>,
    r_w: Vec<f32>,
    passes: u32,
    beta: f32,
    m: Vec<f32>,
    m2: Vec<f32>,
}

/// Scratch for the regional (smoothed-root) continental isostasy.
#[derive(Clone, Debug, Default)]
pub struct RegionalIsostasy {
    root: Vec<f32>,
    next: Vec<f32>,
    max_rate: Option<(usize, f64)>,
    coarse: Option<CoarseLevel>,
}

/// Fine-level passes above which [`RegionalIsostasy::with_coarse_level`] builds a coarse mesh.
pub const MAX_FINE_PASSES: u32 = 6;

fn mean_sq(edge_km: &[f32]) -> f64 {
    if edge_km.is_empty() {
        0.0
    } else {
        edge_km
            .iter()
            .map(|&d| (d as f64) * (d as f64))
            .sum::<f64>()
            / edge_km.len() as f64
    }
}

impl RegionalIsostasy {
    /// New scratch that smooths on the fine graph only (fine for ≤ ~100k samples or small T_e).
    pub fn new() -> Self {
        Self::default()
    }

    /// Scratch with a coarse level for kernel `p.regional_sigma_km()` on the mesh of unit
    /// `positions` (the graph's samples), built when the fine graph would need more than
    /// [`MAX_FINE_PASSES`] passes. One-off cost ~0.3 s at 500k samples. If `p`'s elastic
    /// thickness changes later, the fine passes are used instead.
    pub fn with_coarse_level(
        positions: &[glam::DVec3],
        g: &ReliefGraph,
        p: &IsostasyParams,
    ) -> Self {
        let mut s = Self::new();
        let sigma = if p.elastic_thickness_km > 0.0 {
            p.regional_sigma_km()
        } else {
            0.0
        };
        let (fine_passes, _) = s.passes_for(g, sigma);
        if fine_passes > MAX_FINE_PASSES && positions.len() == g.len() {
            s.coarse = CoarseLevel::build(positions, g, sigma);
        }
        s
    }

    /// Plate deflection w = G∗r (km, positive down) of every sample from the last
    /// [`RegionalIsostasy::continental_elevation`]; under oceanic crust it is the flexural moat
    /// of nearby continental loads.
    pub fn deflection_km(&self) -> &[f32] {
        &self.root
    }

    /// Whether a coarse level is in use.
    pub fn has_coarse_level(&self) -> bool {
        self.coarse.is_some()
    }

    /// Fine-graph smoothing passes and step λ (km²) for kernel width `sigma_km` on `g`: explicit
    /// heat-equation passes r_i += λ/a_i·Σ_j w_ij (r_j − r_i) (cotangent weights, exactly
    /// conservative) with k·λ = τ = σ²/2 and λ·max(Σw/a) ≤ 0.9.
    pub fn passes_for(&mut self, g: &ReliefGraph, sigma_km: f64) -> (u32, f64) {
        let n = g.len();
        let max_rate = match self.max_rate {
            Some((len, v)) if len == n => v,
            _ => {
                let v = (0..n)
                    .into_par_iter()
                    .with_min_len(8192)
                    .filter(|&i| g.area_km2[i] > 0.0)
                    .map(|i| {
                        g.edges(i).map(|e| g.edge_weight[e] as f64).sum::<f64>() / g.area_km2[i]
                    })
                    .reduce(|| 0.0, f64::max);
                self.max_rate = Some((n, v));
                v
            }
        };
        if !(sigma_km > 0.0) || max_rate <= 0.0 {
            return (0, 0.0);
        }
        let tau = 0.5 * sigma_km * sigma_km;
        let k = ((tau * max_rate / 0.9).ceil() as u32).clamp(1, 10_000);
        (k, tau / k as f64)
    }

    /// Writes the surface elevation (km) of every continental sample of `thickness_km` to
    /// `elevation_km` (other samples untouched), with the root smoothed by the regional kernel
    /// of `p` (`p.elastic_thickness_km` = 0: local Airy). The deflection w = G∗r of every
    /// sample is left in [`RegionalIsostasy::deflection_km`]: subtract it from the oceanic
    /// elevation (it is 0 far from continents). Returns the number of smoothing passes used
    /// (on the coarse level when there is one).
    ///
    /// Fine level: conservative diffusion passes (exact Σ a·r). Coarse level: area-weighted
    /// restrict–smooth–interpolate (Σ a·r to ~1%, measured in the tests).
    pub fn continental_elevation(
        &mut self,
        g: &ReliefGraph,
        thickness_km: &[f32],
        continental: &[bool],
        p: &IsostasyParams,
        elevation_km: &mut [f32],
    ) -> u32 {
        let n = g.len();
        if thickness_km.len() < n || continental.len() < n || elevation_km.len() < n {
            return 0;
        }
        let passes = self.smooth_root(g, thickness_km, continental, p);
        let c = p.constants(0.0);
        let root = &self.root;
        elevation_km
            .par_iter_mut()
            .enumerate()
            .with_min_len(8192)
            .for_each(|(i, z)| {
                if !continental[i] {
                    return;
                }
                let t = thickness_km[i] as f64;
                if t.is_finite() {
                    *z = continental_surface_km(t, root[i], &c);
                }
            });
        passes
    }

    /// The smoothing of [`RegionalIsostasy::continental_elevation`] without the combine: the
    /// root r = (T − T₀)·ρ_c/ρ_m of every continental sample of `thickness_km` (0 elsewhere)
    /// smoothed by the regional kernel of `p` into the deflection w = G∗r, left in
    /// [`RegionalIsostasy::deflection_km`]. Returns the number of smoothing passes used (0 when
    /// an input is shorter than the graph, leaving the deflection as it was).
    #[allow(clippy::needless_range_loop)]
    pub fn smooth_root(
        &mut self,
        g: &ReliefGraph,
        thickness_km: &[f32],
        continental: &[bool],
        p: &IsostasyParams,
    ) -> u32 {
        let n = g.len();
        if thickness_km.len() < n || continental.len() < n {
            return 0;
        }
        let t0 = p.ref_thickness_km;
        let c = p.rho_crust / p.rho_mantle;
        self.root.resize(n, 0.0);
        self.next.resize(n, 0.0);
        let root_of = |i: usize| -> f32 {
            let t = thickness_km[i] as f64;
            if continental[i] && t.is_finite() {
                ((t - t0) * c) as f32
            } else {
                0.0
            }
        };
        let sigma = if p.elastic_thickness_km > 0.0 {
            p.regional_sigma_km()
        } else {
            0.0
        };
        let mut passes = 0;
        let use_coarse = matches!(&self.coarse, Some(cl) if cl.n_fine == n && (cl.sigma_km - sigma).abs() < 1e-9);
        if sigma > 0.0 && use_coarse {
            if let Some(cl) = self.coarse.as_mut() {
                // Each fine sample feeds about three coarse ones: its root is computed once,
                // into the scratch buffer, rather than at each.
                self.next
                    .par_iter_mut()
                    .enumerate()
                    .with_min_len(8192)
                    .for_each(|(i, r)| *r = root_of(i));
                let roots = &self.next;
                passes = cl.smooth(&|i| roots[i], &mut self.root);
            }
        } else {
            self.root
                .par_iter_mut()
                .enumerate()
                .with_min_len(8192)
                .for_each(|(i, r)| *r = root_of(i));
        }
        if sigma > 0.0 && !use_coarse {
            let (k, lambda) = self.passes_for(g, sigma);
            passes = k;
            for _ in 0..k {
                let r = &self.root;
                self.next
                    .par_chunks_mut(8192)
                    .enumerate()
                    .for_each(|(ch, out)| {
                        let base = ch * 8192;
                        for k in 0..out.len() {
                            let i = base + k;
                            let ri = r[i];
                            if g.area_km2[i] <= 0.0 {
                                out[k] = ri;
                                continue;
                            }
                            let mut f = 0.0f64;
                            for e in g.edges(i) {
                                let j = g.neighbors[e] as usize;
                                f += g.edge_weight[e] as f64 * (r[j] - ri) as f64;
                            }
                            out[k] = (ri as f64 + lambda * f / g.area_km2[i]) as f32;
                        }
                    });
                std::mem::swap(&mut self.root, &mut self.next);
            }
        }
        passes
    }
}

/// Surface elevation (km) of a continental column `t_km` thick (finite) whose smoothed root is
/// `root_km`: the root is held within `c.max_support_km` of the column's own, the column floats
/// on it, and below sea level the water load deepens it.
#[inline]
fn continental_surface_km(t_km: f64, root_km: f32, c: &IsostasyConstants) -> f32 {
    let t_km = if t_km > c.max_continental_km {
        c.max_continental_km
    } else {
        t_km
    };
    let t0 = c.ref_thickness_km;
    let own = (t_km - t0) * c.root_ratio;
    let w = (root_km as f64).clamp(own - c.max_support_km, own + c.max_support_km);
    let dry = c.ref_elevation_km + (t_km - t0) - w;
    let z = if dry >= 0.0 {
        dry
    } else {
        dry * c.rho_mantle / (c.rho_mantle - c.rho_water)
    };
    z as f32
}

/// The CPU kernel (reference of `shaders/isostasy.wgsl`): the elevation of every sample from
/// the crust, given the smoothed root (`deflection_km`, w = G∗r from
/// [`RegionalIsostasy::smooth_root`]) and the trench depth of every sample (km below the floor
/// beside it).
///
/// - Continental samples of finite thickness T (counted up to `c.max_continental_km`: a
///   thicker column loses its excess root to the mantle, as over-thickened orogens delaminate):
///   h₀ + (T − T₀) − w', w' = w held within `c.max_support_km` of the sample's own root
///   (T − T₀)·ρ_c/ρ_m, with the water load below sea level; a non-finite thickness leaves the
///   elevation as it is.
/// - Oceanic samples: −depth(age) (from `table`) + gain·min(T − T_oc, `c.max_oceanic_load_km`)
///   − clamp(w, ±S) − trench (a sediment pile or arc thicker than the cap is held at it).
///
/// Computed in f64 from the f32 inputs and rounded once. Inputs shorter than `elevation_km`
/// read as w = 0 and no trench.
#[allow(clippy::too_many_arguments)]
pub fn isostasy_cpu(
    c: &IsostasyConstants,
    table: &AgeDepthTable,
    crust_type: &[CrustType],
    thickness_km: &[f32],
    age_my: &[f32],
    deflection_km: &[f32],
    trench_km: &[f32],
    elevation_km: &mut [f32],
) {
    let support = c.max_support_km;
    elevation_km
        .par_iter_mut()
        .enumerate()
        .with_min_len(8192)
        .for_each(|(i, z)| {
            let w = deflection_km.get(i).copied().unwrap_or(0.0);
            if crust_type[i] == CrustType::Oceanic {
                let load = thickness_km[i] as f64 - c.oceanic_thickness_km;
                // (NaN stays NaN, as on the GPU.)
                let excess = if load > c.max_oceanic_load_km {
                    c.max_oceanic_load_km
                } else {
                    load
                };
                let wi = (w as f64).clamp(-support, support);
                let trench = trench_km.get(i).copied().unwrap_or(0.0);
                *z = (-table.depth_km(age_my[i] as f64) + c.sediment_gain * excess
                    - wi
                    - trench as f64) as f32;
            } else {
                let t = thickness_km[i] as f64;
                if t.is_finite() {
                    *z = continental_surface_km(t, w, c);
                }
            }
        });
}

impl CoarseLevel {
    fn build(positions: &[glam::DVec3], g: &ReliefGraph, sigma_km: f64) -> Option<Self> {
        let n = positions.len();
        let r = g.radius_km;
        // Coarse spacing ≈ 0.8 σ; N from the hexagonal-lattice relation area = (√3/2)·d².
        let hc = 0.8 * sigma_km;
        let nc = ((4.0 * std::f64::consts::PI * r * r) / (0.866 * hc * hc)) as usize;
        // Worth it once that mesh is 1.5× coarser than the graph: its three or so passes, the
        // restriction and the interpolation then cost about as much as five fine passes, where
        // the fine level needs about twelve (the rule was 3× until the 262,144-sample planet was
        // measured spending 17–20 ms a step on 18 fine passes). The kernel's shape does not
        // depend on the graph: the coarse spacing is set by σ alone.
        if nc < 1000 || 3 * nc > 2 * n {
            return None;
        }
        let cm = crate::geometry::SphereMesh::fibonacci(nc, 0.0, 0, r).ok()?;
        // Triangle adjacency across each edge.
        let tris = &cm.triangles;
        let mut dir: Vec<(u64, u32)> = Vec::with_capacity(tris.len() * 3);
        for (t, tri) in tris.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k] as u64, tri[(k + 1) % 3] as u64);
                dir.push(((a << 32) | b, t as u32));
            }
        }
        dir.sort_unstable();
        let find = |a: u32, b: u32| -> u32 {
            let key = ((a as u64) << 32) | b as u64;
            dir.binary_search_by(|e| e.0.cmp(&key))
                .map(|k| dir[k].1)
                .unwrap_or(u32::MAX)
        };
        let adj: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| [find(t[1], t[0]), find(t[2], t[1]), find(t[0], t[2])])
            .collect();
        let cp = &cm.positions;
        let tri_of = |t: usize| {
            (
                cp[tris[t][0] as usize],
                cp[tris[t][1] as usize],
                cp[tris[t][2] as usize],
            )
        };
        // Walk-locate every fine sample (fine samples are Morton-sorted, so walks are short).
        let mut p_idx = Vec::with_capacity(n);
        let mut p_w = Vec::with_capacity(n);
        let mut t = 0usize;
        for &q in positions {
            let mut steps = 0;
            'walk: loop {
                steps += 1;
                let (a, b, c) = tri_of(t);
                let corners = [a, b, c];
                for k0 in 0..3 {
                    let k = (k0 + steps) % 3;
                    let (u, v) = (corners[k], corners[(k + 1) % 3]);
                    if u.cross(v).dot(q) < -1e-15 {
                        let nt = adj[t][k];
                        if nt != u32::MAX && steps < 100_000 {
                            t = nt as usize;
                            continue 'walk;
                        }
                    }
                }
                break;
            }
            let (a, b, c) = tri_of(t);
            let mut w = [
                q.dot(b.cross(c)).max(0.0),
                a.dot(q.cross(c)).max(0.0),
                a.dot(b.cross(q)).max(0.0),
            ];
            let s = w[0] + w[1] + w[2];
            if s > 0.0 {
                w.iter_mut().for_each(|x| *x /= s);
            } else {
                w = [1.0, 0.0, 0.0];
            }
            p_idx.push(tris[t]);
            p_w.push([w[0] as f32, w[1] as f32, w[2] as f32]);
        }
        // Coarse passes: the interpolation and its transpose each add about h²/6 of variance
        // per axis (hat functions); the passes supply the rest.
        let mut coarse_edges = Vec::with_capacity(cm.neighbors.len());
        for i in 0..nc {
            for &j in cm.neighbors_of(i) {
                coarse_edges
                    .push(crate::geometry::angle_between(cp[i], cp[j as usize]) as f32 * r as f32);
            }
        }
        let msq = mean_sq(&coarse_edges);
        drop(coarse_edges);
        // Only the coarse adjacency stays: the rest of the coarse mesh and the triangle search
        // go before the restriction is allocated (they were the peak of the run's first step).
        drop(adj);
        drop(dir);
        let cm = cm.into_data();
        let (c_start, c_nbrs) = (cm.neighbor_start, cm.neighbors);
        // Restriction = transpose of the interpolation.
        let mut r_start = vec![0u32; nc + 1];
        for ids in &p_idx {
            for &c in ids {
                r_start[c as usize + 1] += 1;
            }
        }
        for c in 0..nc {
            r_start[c + 1] += r_start[c];
        }
        let mut fill = r_start[..nc].to_vec();
        let mut r_fine = vec![0u32; 3 * n];
        let mut r_w = vec![0f32; 3 * n];
        for (i, (ids, ws)) in p_idx.iter().zip(&p_w).enumerate() {
            for k in 0..3 {
                let c = ids[k] as usize;
                r_fine[fill[c] as usize] = i as u32;
                r_w[fill[c] as usize] = ws[k];
                fill[c] += 1;
            }
        }
        let remaining = (sigma_km * sigma_km - msq / 3.0).max(0.0);
        let per_pass = 0.5 * msq;
        let passes = if remaining > 0.0 {
            (remaining / per_pass).ceil() as u32
        } else {
            0
        };
        let beta = if passes > 0 {
            (remaining / (passes as f64 * per_pass)) as f32
        } else {
            0.0
        };
        let mut level = Self {
            sigma_km,
            n_fine: n,
            c_start,
            c_nbrs,
            p_idx,
            p_w,
            r_start,
            r_fine,
            r_w,
            passes,
            beta,
            m: vec![0.0; nc],
            m2: vec![0.0; nc],
        };
        // Fold the fine areas into the restriction weights, and 1/G∗a into the interpolation.
        for k in 0..level.r_w.len() {
            level.r_w[k] *= g.area_km2[level.r_fine[k] as usize] as f32;
        }
        let ones = vec![1.0f32; n];
        level.restrict_and_smooth(&|i| ones[i]);
        let a_s = level.m.clone();
        for i in 0..n {
            let ids = level.p_idx[i];
            let den: f32 = (0..3).map(|k| level.p_w[i][k] * a_s[ids[k] as usize]).sum();
            if den > 0.0 {
                for k in 0..3 {
                    level.p_w[i][k] /= den;
                }
            }
        }
        Some(level)
    }

    /// m = S^k (Pᵀ·(a·f)) on the coarse mesh, for fine field f.
    fn restrict_and_smooth<F: Fn(usize) -> f32 + Sync>(&mut self, f: &F) {
        {
            let (rs, rf, rw) = (&self.r_start, &self.r_fine, &self.r_w);
            self.m
                .par_iter_mut()
                .enumerate()
                .with_min_len(2048)
                .for_each(|(c, m)| {
                    let mut sm = 0.0f32;
                    for k in rs[c] as usize..rs[c + 1] as usize {
                        sm += rw[k] * f(rf[k] as usize);
                    }
                    *m = sm;
                });
        }
        let beta = self.beta;
        for _ in 0..self.passes {
            let (m, cs, cn) = (&self.m, &self.c_start, &self.c_nbrs);
            self.m2
                .par_iter_mut()
                .enumerate()
                .with_min_len(2048)
                .for_each(|(c, m2)| {
                    let (s, e) = (cs[c] as usize, cs[c + 1] as usize);
                    let mut sm = 0.0f32;
                    for &j in &cn[s..e] {
                        sm += m[j as usize];
                    }
                    let k = (e - s).max(1) as f32;
                    *m2 = m[c] + beta * (sm / k - m[c]);
                });
            std::mem::swap(&mut self.m, &mut self.m2);
        }
    }

    /// out = G∗(a·r)/G∗(a) at every sample, r given per fine sample by `root`.
    fn smooth<F: Fn(usize) -> f32 + Sync>(&mut self, root: &F, out: &mut [f32]) -> u32 {
        self.restrict_and_smooth(root);
        let (m, pi, pw) = (&self.m, &self.p_idx, &self.p_w);
        out.par_chunks_mut(8192).enumerate().for_each(|(ch, o)| {
            let base = ch * 8192;
            for k in 0..o.len() {
                let (ids, ws) = (pi[base + k], pw[base + k]);
                o[k] = ws[0] * m[ids[0] as usize]
                    + ws[1] * m[ids[1] as usize]
                    + ws[2] * m[ids[2] as usize];
            }
        });
        self.passes
    }
}
