//! Crust aging (Driftworld §3.15): every sample's crust age grows by δt, and so does the orogeny
//! age where an orogeny is recorded.

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use crate::io::params::Params;
use crate::resources::{Crust, Orogeny};

/// Ages the crust by one time step.
pub fn age_crust(params: Res<Params>, mut crust: ResMut<Crust>) {
    let dt = params.time.time_step_my as f32;
    let crust = &mut *crust;
    crust
        .age_my
        .par_iter_mut()
        .with_min_len(4096)
        .for_each(|a| *a += dt);
    crust
        .orogeny_age_my
        .par_iter_mut()
        .zip(crust.orogeny.par_iter())
        .with_min_len(4096)
        .for_each(|(a, &o)| {
            if o != Orogeny::None {
                *a += dt;
            }
        });
}
