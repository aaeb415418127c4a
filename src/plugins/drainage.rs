//! The drainage network (phenomenon [`DRAINAGE`]): each land sample drains to one neighbour by
//! great-circle slope, closed depressions become lakes that overflow, every river ends in the
//! sea. Systems: [`crate::systems::relief`] ([`build_drainage`](relief::build_drainage), on
//! [`relief::drainage`]). Rebuilt on one step in `time.relief_interval_steps` (every step by
//! default) and after each resampling; the rivers and the sediment follow it, and the maps draw
//! it.

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    AfterResample, AfterResampleSystems, Phenomenon, PhenomenonAppExt, ResampleSystems,
    TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::geometry::SphereMesh;
use crate::resources::{
    Params, SaveAppExt, SaveSection, SectionError, SectionReader, SectionWriter, SimClock,
};
use crate::systems::relief;

/// The phenomenon key.
pub const DRAINAGE: Phenomenon = Phenomenon::new("drainage");

/// The drainage network of the surface (phenomenon `drainage`).
#[derive(Default)]
pub struct DrainagePlugin;

impl Plugin for DrainagePlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            DRAINAGE,
            TectonicSystems::Drainage,
            "rivers: each land sample drains to the sea; depressions fill to lakes",
        );
        app.init_resource::<relief::ReliefState>()
            .init_resource::<relief::DrainageNetwork>()
            .init_resource::<relief::SurfaceFlux>();
        app.register_save_section(SaveSection {
            name: "relief.network",
            version: 1,
            save: save_network,
            load: load_network,
            default: Some(|_| Ok(())),
        });
        app.add_systems(
            TectonicStep,
            (
                relief::restore_network.run_if(not(relief::drainage_due)),
                relief::build_drainage.run_if(relief::drainage_due),
            )
                .chain()
                .in_set(TectonicSystems::Drainage)
                .run_if(phenomenon_enabled(DRAINAGE)),
        );
        // Before a resampling (after the carried rock is laid down on the network), the network
        // and the relief's work areas make way for the resampling's buffers.
        app.add_systems(
            TectonicStep,
            relief::release_relief_before_resample
                .in_set(TectonicSystems::Resample)
                .before(ResampleSystems::Interpolate)
                .after(relief::deposit_carried_sediment)
                .run_if(phenomenon_enabled(DRAINAGE))
                .run_if(crate::systems::resample::resample_due),
        );
        // A resampling moves the samples the network and the carried rock are recorded on.
        app.add_systems(
            AfterResample,
            relief::forget_network
                .in_set(AfterResampleSystems::Relief)
                .run_if(crate::systems::resample::just_resampled),
        );
    }
}

/// Section `relief.network`: what crosses a step boundary with `time.relief_interval_steps`
/// above 1. The rock eroded since the last routing and not laid down yet ([`relief::SurfaceFlux`]:
/// per sample, what the rivers, slopes and coasts removed and what crossed the coast; the
/// volumes), and what the network the rivers and coasts follow was built from
/// ([`relief::NetworkSource`]: the surface, the oceanic samples, the rain), from which a load
/// builds the same network again. Both are empty at the end of a step of the default setting
/// (every step builds its network and lays its rock down). Saves without the section resume
/// with nothing carried and a network built on the next step.
fn save_network(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    match world.get_resource::<relief::SurfaceFlux>() {
        Some(f) if f.pending => {
            w.u8(1);
            w.u8(f.carried as u8);
            w.u32s(&f32_bits(&f.eroded_km));
            w.u32s(&f32_bits(&f.diffusion_km));
            w.u32(f.to_ocean_km3.len() as u32);
            for &v in &f.to_ocean_km3 {
                w.f64(v);
            }
            w.f64(f.incised_km3);
            w.f64(f.coastal_km3);
            w.f64(f.diffusion.lowered_km3);
            w.f64(f.diffusion.raised_km3);
            w.f64(f.diffusion.to_ocean_km3);
            w.u32(f.diffusion.substeps);
        }
        _ => w.u8(0),
    }
    match world.get_resource::<relief::DrainageNetwork>() {
        Some(net) if net.built && net.source.is_some() => {
            let src = net.source.as_ref().expect("checked");
            w.u8(1);
            w.u64(net.built_step);
            w.u32s(&f32_bits(&src.elevation_km));
            w.u32(src.oceanic.len() as u32);
            w.bytes(&src.oceanic.iter().map(|&o| o as u8).collect::<Vec<u8>>());
            w.u32s(&f32_bits(&src.rain));
        }
        _ => w.u8(0),
    }
    Ok(())
}

fn load_network(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let n = world.resource::<SphereMesh>().len();
    let step = world.resource::<SimClock>().step;
    let flag = |b: u8, what: &str| -> Result<bool, SectionError> {
        match b {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(format!("{what}: byte {b}").into()),
        }
    };
    let per_sample = |v: Vec<u32>, what: &str, allow_empty: bool| {
        if v.len() != n && !(allow_empty && v.is_empty()) {
            return Err(SectionError::from(format!(
                "{what}: {} values for {n} samples",
                v.len()
            )));
        }
        let out: Vec<f32> = v.into_iter().map(f32::from_bits).collect();
        if out.iter().any(|x| !x.is_finite()) {
            return Err(format!("{what}: a value is not finite").into());
        }
        Ok(out)
    };
    let mut flux = None;
    if flag(r.u8()?, "carried rock")? {
        let carried = flag(r.u8()?, "carried flag")?;
        let eroded_km = per_sample(r.u32s()?, "carried erosion", false)?;
        let diffusion_km = per_sample(r.u32s()?, "carried diffusion", false)?;
        let m = r.u32()? as usize;
        if m != n || r.remaining() < m.saturating_mul(8) {
            return Err(format!("carried coast crossings: {m} values for {n} samples").into());
        }
        let mut to_ocean_km3 = Vec::with_capacity(m);
        for _ in 0..m {
            to_ocean_km3.push(r.finite_f64("carried coast crossing")?);
        }
        let incised = r.finite_f64("carried incision")?;
        let coastal = r.finite_f64("carried coastal erosion")?;
        let budget = relief::diffusion::DiffusionBudget {
            lowered_km3: r.finite_f64("carried diffusion")?,
            raised_km3: r.finite_f64("carried diffusion")?,
            to_ocean_km3: r.finite_f64("carried diffusion")?,
            substeps: r.u32()?,
        };
        flux = Some((
            carried,
            eroded_km,
            diffusion_km,
            to_ocean_km3,
            incised,
            coastal,
            budget,
        ));
    }
    let mut source = None;
    if flag(r.u8()?, "network source")? {
        let built_step = r.u64()?;
        if built_step > step {
            return Err(format!("network built on step {built_step}, after step {step}").into());
        }
        let elevation_km = per_sample(r.u32s()?, "network surface", false)?;
        let m = r.u32()? as usize;
        if m != n {
            return Err(format!("network oceanic samples: {m} values for {n} samples").into());
        }
        let oceanic = r
            .take(m)?
            .iter()
            .map(|&b| flag(b, "network oceanic sample"))
            .collect::<Result<Vec<bool>, _>>()?;
        let rain = per_sample(r.u32s()?, "network rain", true)?;
        source = Some((
            built_step,
            relief::NetworkSource {
                elevation_km,
                oceanic,
                rain,
            },
        ));
    }
    r.finish()?;
    if let Some((carried, eroded_km, diffusion_km, to_ocean_km3, incised, coastal, budget)) = flux
        && let Some(mut f) = world.get_resource_mut::<relief::SurfaceFlux>()
    {
        f.begin_step(n);
        f.eroded_km = eroded_km;
        f.diffusion_km = diffusion_km;
        f.to_ocean_km3 = to_ocean_km3;
        f.incised_km3 = incised;
        f.coastal_km3 = coastal;
        f.diffusion = budget;
        f.pending = true;
        f.carried = carried;
    }
    if let Some((built_step, src)) = source {
        let params = world.resource::<Params>().clone();
        world.resource_scope(|world, mut state: Mut<relief::ReliefState>| {
            let mesh = world.resource::<SphereMesh>().clone();
            let mut net = world.resource_mut::<relief::DrainageNetwork>();
            net.rebuild(&params, &mesh, &mut state, src, built_step);
        });
    }
    Ok(())
}

fn f32_bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}
