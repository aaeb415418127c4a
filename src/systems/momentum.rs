//! Plate momentum (seed 004): with `plates.momentum` on, plates carry angular momentum, and it is
//! conserved wherever crust changes plate.
//!
//! A plate's angular momentum is L = I·ω, with ω its angular velocity (Euler pole × angular
//! speed) and I its inertia tensor about the planet's centre, Σ mᵢ (E − pᵢpᵢᵀ) over its samples
//! (pᵢ unit positions; the constant R² is left out of every I and so of every ratio). A sample's
//! mass is its area times its crust's nominal thickness (`init.continental_thickness_km` or
//! `init.oceanic_thickness_km`): continental plates are about five times heavier per area, so
//! they turn oceanic plates more than the other way round. (Nominal, not live, thickness: the
//! exchanges then read only plate and crust type, which every backend keeps on the host.)
//!
//! - **Suture** (a terrane T leaves plate A for plate B): T takes its momentum I_T·ω_A with it,
//!   and the collision exchanges an angular impulse P between the two plates (equal and
//!   opposite, so the total is unchanged) that takes away the fraction
//!   `plates.collision_coupling` of what is left of their relative angular velocity: converging
//!   continents slow down and dock instead of ploughing on. With I_A (A without T) and I_B (B
//!   with T): ω_B ← ω_B + I_B⁻¹·I_T·(ω_A − ω_B), then P = f·(I_A⁻¹ + I_B⁻¹)⁻¹·(ω_A − ω_B),
//!   ω_A ← ω_A − I_A⁻¹P, ω_B ← ω_B + I_B⁻¹P. I_A·ω_A + I_B·ω_B is the momentum before.
//! - **Rift** (plate → fragments k): each fragment gets the parent's ω plus its divergence δ_k,
//!   less the common c = (Σ I_k)⁻¹ Σ I_k δ_k, so Σ I_k ω_k = I_parent·ω_parent: the fragments
//!   push apart without the plate as a whole speeding up.
//!
//! Slab pull still turns a subducting plate's pole (an outside torque), so the total is not
//! constant over a run, only at each exchange.

use glam::{DMat3, DVec3};

use crate::components::PlateMotion;
use crate::resources::CrustType;
use crate::resources::params::Params;

/// Angular velocity vector (rad/My) of a motion.
pub fn omega(m: &PlateMotion) -> DVec3 {
    m.euler_pole * m.angular_speed_rad_per_my
}

/// The motion of angular velocity `w` (keeping `fallback_pole` when `w` is zero).
pub fn motion_of(w: DVec3, fallback_pole: DVec3) -> PlateMotion {
    let speed = w.length();
    PlateMotion {
        euler_pole: if speed > 1e-300 {
            w / speed
        } else {
            fallback_pole
        },
        angular_speed_rad_per_my: speed,
    }
}

/// Mass (area × nominal thickness, km³) of a sample of `area_km2` and crust type `ct`.
pub fn sample_mass(ct: CrustType, area_km2: f64, params: &Params) -> f64 {
    area_km2 * params.nominal_thickness_km(ct)
}

/// Inertia tensor Σ m (E − p pᵀ) of point masses `(unit position, mass)`.
pub fn inertia(points: impl IntoIterator<Item = (DVec3, f64)>) -> DMat3 {
    let mut i = DMat3::ZERO;
    for (p, m) in points {
        i += (DMat3::IDENTITY - DMat3::from_cols(p * p.x, p * p.y, p * p.z)) * m;
    }
    i
}

/// I⁻¹ (a tensor of a plate a few samples wide is nearly singular about its own axis: it is
/// regularised by 10⁻¹² of its trace).
fn inverse(i: DMat3) -> DMat3 {
    let tr = i.x_axis.x + i.y_axis.y + i.z_axis.z;
    if !(tr > 0.0) {
        return DMat3::ZERO;
    }
    (i + DMat3::IDENTITY * (1e-12 * tr)).inverse()
}

/// New angular velocities (ω_A, ω_B) after terrane T (inertia `i_t`) left plate A for plate B;
/// `i_a` is A's inertia without T, `i_b` B's with T, `coupling` the fraction of the relative
/// angular velocity the collision takes away (see the module documentation). Conserves
/// `(i_a + i_t)·w_a + (i_b − i_t)·w_b`.
pub fn suture_exchange(
    i_a: DMat3,
    i_b: DMat3,
    i_t: DMat3,
    w_a: DVec3,
    w_b: DVec3,
    coupling: f64,
) -> (DVec3, DVec3) {
    let (inv_a, inv_b) = (inverse(i_a), inverse(i_b));
    if inv_b == DMat3::ZERO {
        return (w_a, w_b);
    }
    // The terrane's momentum goes with it.
    let w_b = w_b + inv_b * (i_t * (w_a - w_b));
    if inv_a == DMat3::ZERO || coupling <= 0.0 {
        return (w_a, w_b);
    }
    // The collision's impulse.
    let reduced = inverse(inv_a + inv_b);
    let p = reduced * (w_a - w_b) * coupling.min(1.0);
    (w_a - inv_a * p, w_b + inv_b * p)
}

/// Fragments of a rift: `omegas` (the parent's ω plus each fragment's divergence) less the
/// common part that would change the total momentum, so that Σ Iₖωₖ = (Σ Iₖ)·`w_parent`.
pub fn rift_correction(inertias: &[DMat3], omegas: &mut [DVec3], w_parent: DVec3) {
    let total: DMat3 = inertias.iter().fold(DMat3::ZERO, |a, &b| a + b);
    let inv = inverse(total);
    if inv == DMat3::ZERO {
        return;
    }
    let excess: DVec3 = inertias
        .iter()
        .zip(omegas.iter())
        .map(|(&i, &w)| i * (w - w_parent))
        .fold(DVec3::ZERO, |a, b| a + b);
    let c = inv * excess;
    for w in omegas.iter_mut() {
        *w -= c;
    }
}
