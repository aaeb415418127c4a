//! Plate rifting (phenomenon [`RIFTING`], paper §4.4): plates break into 2–4 diverging fragments
//! at random (a Poisson process favouring large, continental plates). Systems:
//! [`crate::systems::rifting`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::resample::RESAMPLE;
use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::resources::{
    RiftSiblings, SaveAppExt, SaveSection, SectionError, SectionReader, SectionWriter,
};
use crate::systems::rifting;

/// The phenomenon key.
pub const RIFTING: Phenomenon = Phenomenon::new("rifting");

/// Plate rifting (phenomenon `rifting`): plates break into 2–4 diverging fragments at random
/// (a Poisson process favouring large, continental plates; see [`rifting`]).
#[derive(Default)]
pub struct RiftingPlugin;

impl Plugin for RiftingPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            RIFTING,
            TectonicSystems::Rifting,
            "large plates break into diverging fragments",
        );
        app.init_resource::<rifting::RiftLog>();
        app.init_resource::<RiftSiblings>();
        app.register_save_section(siblings_section());
        // Random rifts happen on the steps that end with a resampling (which rebuilds the
        // fragments' fronts and terranes), or every step when the resampling is off.
        app.add_systems(
            TectonicStep,
            (
                rifting::rift_plates.run_if(phenomenon_enabled(RESAMPLE)),
                rifting::rift_plates_every_step.run_if(not(phenomenon_enabled(RESAMPLE))),
            )
                .chain()
                .in_set(TectonicSystems::Rifting)
                .run_if(phenomenon_enabled(RIFTING)),
        );
    }
}

/// The rifts' fragment pairs still exempt from subduction fronts ([`RiftSiblings`]; section
/// `rifting.siblings`): per pair the two plate ids and the simulated time at which the
/// exemption ends. Saves made before it load with none (their rifts' fragments meet at fronts
/// from the next resampling on, as they did then).
pub fn siblings_section() -> SaveSection {
    SaveSection {
        name: "rifting.siblings",
        version: 1,
        save: save_siblings,
        load: load_siblings,
        default: Some(|world| {
            world.insert_resource(RiftSiblings::default());
            Ok(())
        }),
    }
}

fn save_siblings(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let pairs = world
        .get_resource::<RiftSiblings>()
        .map(|s| s.pairs.clone())
        .unwrap_or_default();
    w.u32(pairs.len() as u32);
    for ((a, b), until) in pairs {
        w.u32(a);
        w.u32(b);
        w.f64(until);
    }
    Ok(())
}

fn load_siblings(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let count = r.u32()? as usize;
    // 16 bytes a pair must be there before allocating.
    if count.saturating_mul(16) > r.remaining() {
        return Err(format!(
            "{count} sibling pairs claimed, {} bytes left",
            r.remaining()
        )
        .into());
    }
    let mut pairs: Vec<((u32, u32), f64)> = Vec::with_capacity(count);
    for _ in 0..count {
        let (a, b) = (r.u32()?, r.u32()?);
        let until = r.finite_f64("a sibling pair's end")?;
        if a >= b {
            return Err(format!("sibling pair ({a}, {b}) is not in ascending order").into());
        }
        if pairs.last().is_some_and(|&(k, _)| k >= (a, b)) {
            return Err("sibling pairs are not sorted and unique".into());
        }
        pairs.push(((a, b), until));
    }
    world.insert_resource(RiftSiblings { pairs });
    Ok(())
}
