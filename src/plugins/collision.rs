//! Continental collisions (phenomenon [`COLLISION`], paper §4.2): a terrane more than the
//! interpenetration threshold under another plate's continent sutures to it at a resampling (the
//! next regular one, the terrane moving with that plate meanwhile; with
//! `collision.resample_at_suture` on, one the collision forces in its step), with a Himalayan
//! surge around it. Systems:
//! [`crate::systems::convergence::collision`]; GPU kernel: [`crate::gpu::collision_uplift`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::convergence_state::convergence_section;
use super::resample::RESAMPLE;
use super::schedule::{
    AfterResample, AfterResampleSystems, Phenomenon, PhenomenonAppExt, ResampleSystems,
    TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::resources::SaveAppExt;
use crate::systems::convergence::collision;
use crate::systems::resample;

/// The phenomenon key.
pub const COLLISION: Phenomenon = Phenomenon::new("collision");

/// Continental collisions (phenomenon `collision`): a terrane more than the interpenetration
/// threshold under another plate's continent sutures to it, with a Himalayan surge around it.
#[derive(Default)]
pub struct CollisionPlugin;

impl Plugin for CollisionPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            COLLISION,
            TectonicSystems::Collision,
            "continental collisions: terranes suture, Himalayan uplift",
        );
        app.register_save_section(convergence_section());
        app.add_systems(
            TectonicStep,
            (
                collision::detect_collisions
                    .in_set(TectonicSystems::Collision)
                    .run_if(phenomenon_enabled(COLLISION)),
                collision::detach_sutured_terranes
                    .in_set(TectonicSystems::Collision)
                    .after(collision::detect_collisions)
                    .run_if(phenomenon_enabled(COLLISION)),
                collision::collide_before_resample
                    .in_set(ResampleSystems::Interpolate)
                    .before(resample::resample_interpolate)
                    .run_if(phenomenon_enabled(COLLISION))
                    .run_if(phenomenon_enabled(RESAMPLE))
                    .run_if(resample::resample_due),
            ),
        );
        app.add_systems(
            AfterResample,
            collision::collision_uplift
                .in_set(AfterResampleSystems::Collision)
                .run_if(phenomenon_enabled(COLLISION)),
        );
    }
}
