//! Isostasy (phenomenon [`ISOSTASY`]): the elevation follows from the crust. Continents float
//! on the mantle (Airy, with a regional response standing in for flexure); ocean floor sinks
//! with age (plate cooling), raised by its load; a trench is cut in front of each active
//! subduction front. With it on, subduction, collisions, erosion and deposition change the
//! crust's thickness and the elevation is derived; off, the kernels raise the elevation as the
//! paper does. Systems: [`crate::systems::relief`] ([`apply_isostasy`](relief::apply_isostasy),
//! with the trench started beside the sediment by [`begin_trench`](relief::begin_trench),
//! on [`relief::isostasy`]).

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    AfterResample, AfterResampleSystems, Phenomenon, PhenomenonAppExt, TectonicStep,
    TectonicSystems, phenomenon_enabled,
};
use crate::resources::{
    Crust, CrustType, Params, SaveAppExt, SaveSection, SectionError, SectionReader, SectionWriter,
};
use crate::systems::relief;
use crate::systems::relief::isostasy::{airy_thickness, ocean_floor_km};

/// The phenomenon key.
pub const ISOSTASY: Phenomenon = Phenomenon::new("isostasy");

/// Elevation from the crust (phenomenon `isostasy`).
#[derive(Default)]
pub struct IsostasyPlugin;

impl Plugin for IsostasyPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            ISOSTASY,
            TectonicSystems::Isostasy,
            "elevation from crust thickness (continents) and sea-floor age (ocean)",
        );
        app.init_resource::<relief::ReliefState>();
        app.register_save_section(SaveSection {
            name: "relief.state",
            version: 1,
            save: save_relief,
            load: load_relief,
            default: Some(derive_thickness),
        });
        app.add_systems(
            TectonicStep,
            relief::apply_isostasy
                .in_set(TectonicSystems::Isostasy)
                .run_if(phenomenon_enabled(ISOSTASY)),
        );
        // The trench's geometry reads nothing the surface processes write: it runs on a
        // thread of its own beside the sediment's routing, which is serial (started before the
        // rivers, it took their parallel loops' second core), and the isostasy takes it.
        app.add_systems(
            TectonicStep,
            relief::begin_trench
                .after(TectonicSystems::Coasts)
                .before(TectonicSystems::Sediment)
                .run_if(phenomenon_enabled(ISOSTASY))
                .run_if(relief::sediment_due),
        );
        // A resampling interpolates the elevation, trenches included, from where the samples
        // were: the trench of floor gone under the overriding plate is lost and what is left shows
        // as lenses. The elevation is derived again on the new crust, with the fronts rebuilt.
        app.add_systems(
            AfterResample,
            (
                crate::systems::convergence::fronts::refresh_fronts,
                relief::apply_isostasy,
            )
                .chain()
                .in_set(AfterResampleSystems::Relief)
                .run_if(phenomenon_enabled(ISOSTASY))
                .run_if(crate::systems::resample::just_resampled),
        );
    }
}

/// Section `relief.state`: the volumes the surface processes moved over the run (eroded,
/// deposited, pelagic), for the statistics. Its presence also says that the crust's thickness is
/// live (made by the relief phenomena); see [`derive_thickness`] for saves without it.
fn save_relief(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let (eroded, deposited) = world
        .get_resource::<relief::SurfaceFlux>()
        .map_or((0.0, 0.0), |f| (f.total_eroded_km3, f.total_deposited_km3));
    w.f64(eroded);
    w.f64(deposited);
    Ok(())
}

fn load_relief(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let eroded = r.finite_f64("eroded volume")?;
    let deposited = r.finite_f64("deposited volume")?;
    r.finish()?;
    if let Some(mut f) = world.get_resource_mut::<relief::SurfaceFlux>() {
        f.total_eroded_km3 = eroded;
        f.total_deposited_km3 = deposited;
    }
    Ok(())
}

/// A save made before the relief phenomena existed kept the crust's thickness constant (35 km
/// continental, 7 km oceanic) and its elevation alone carried the relief. Loading one, the
/// thickness is derived from the elevation so that isostasy keeps the relief: continental crust
/// takes the thickness that stands at its elevation under Airy isostasy; oceanic crust the
/// normal oceanic thickness plus what raises it above the age–depth floor (as sediment: the
/// excess over (ρ_m − ρ_s)/(ρ_m − ρ_w)). Trenches cut by the old kernels are not kept (isostasy
/// cuts its own in front of the fronts).
pub fn derive_thickness(world: &mut World) -> Result<(), SectionError> {
    let Some(params) = world.get_resource::<Params>().cloned() else {
        return Ok(());
    };
    let iso = relief::isostasy_params(&params);
    let t_oc = params.init.oceanic_thickness_km;
    let gain = crate::resources::params::oceanic_load_gain(&params);
    if let Some(mut crust) = world.get_resource_mut::<Crust>() {
        let crust = &mut *crust;
        for i in 0..crust.len() {
            let z = crust.elevation_km[i] as f64;
            if !z.is_finite() {
                continue;
            }
            let t = match crust.crust_type[i] {
                CrustType::Continental => airy_thickness(z, &iso).max(5.0),
                CrustType::Oceanic => {
                    let floor = ocean_floor_km(crust.age_my[i] as f64, &params);
                    t_oc + ((z - floor) / gain).max(0.0)
                }
            };
            crust.thickness_km[i] = t as f32;
        }
    }
    Ok(())
}
