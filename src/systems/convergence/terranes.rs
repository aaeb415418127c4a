//! Terranes: the connected continental regions of each plate, as entities, rebuilt after every
//! resampling, and slivers of ocean trapped inside a continent closed. See [`super`] for the
//! model.
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use glam::DVec3;

use crate::components::{PlateId, Terrane};
use crate::geometry::SphereMesh;
use crate::resources::convergence::NONE;
use crate::resources::params::Params;
use crate::resources::{Crust, CrustType, TerraneField};

/// Welds into the continent every small patch of oceanic crust (smaller than
/// `collision.trapped_ocean_km2`) that the continental crust of a single plate encloses: the
/// remnants of an ocean closed by a collision. Its elevation is taken from the surrounding
/// continent, from the shore inward. Without this, such slivers stay as pits kilometres deep in
/// the middle of mountain belts.
pub fn close_trapped_ocean(world: &mut World) {
    let _timer = crate::systems::DebugTimer::new("close_trapped_ocean");
    let limit = world.resource::<Params>().collision.trapped_ocean_km2;
    if limit <= 0.0 {
        return;
    }
    // First the trapped components (crust type and plate only, which no GPU kernel writes);
    // filling one cannot change the test of another (components are not adjacent), so this
    // finds the same ones as testing and filling in turn.
    let trapped = {
        let crust = world.resource::<Crust>();
        let mesh = world.resource::<SphereMesh>();
        let n = mesh.len();
        let mut seen = vec![false; n];
        let mut trapped: Vec<Vec<usize>> = Vec::new();
        let mut comp = Vec::new();
        for s in 0..n {
            if seen[s] || crust.crust_type[s] != CrustType::Oceanic {
                continue;
            }
            comp.clear();
            comp.push(s);
            seen[s] = true;
            let (mut area, mut enclosed, mut k) = (0.0, true, 0);
            let plate = crust.plate[s];
            while k < comp.len() {
                let u = comp[k];
                k += 1;
                area += mesh.area_km2[u];
                for &v in mesh.neighbors_of(u) {
                    let v = v as usize;
                    if crust.crust_type[v] == CrustType::Oceanic {
                        if !seen[v] {
                            seen[v] = true;
                            comp.push(v);
                        }
                    } else if crust.plate[v] != plate {
                        enclosed = false;
                    }
                }
                if area >= limit {
                    enclosed = false;
                }
            }
            if !enclosed || area >= limit || comp.iter().any(|&u| crust.plate[u] != plate) {
                continue;
            }
            trapped.push(comp.clone());
        }
        trapped
    };
    // Nothing to weld: the crust is left untouched (its change tick does not move, so on the
    // GPU backend the device copy, surged by the collision kernel, stays current).
    if trapped.is_empty() {
        return;
    }
    // The fill reads elevations: on the GPU backend the elevation comes down first (the
    // collision kernel may have raised it). The fill runs on copies of the elevation and crust
    // type (later rings read the samples filled before them), then the written samples go into
    // the crust as a declared write of elevation, crust type and thickness (on the GPU backend
    // those three fields go up, 9 B/sample, instead of a pull of every field and a full upload).
    // (The thickness too: a welded sample takes its neighbours'.)
    if !crate::gpu::sync_crust_to_host_or_record(
        world,
        crate::gpu::FieldMask::ELEVATION | crate::gpu::FieldMask::THICKNESS,
    ) {
        return;
    }
    let fallback = world.resource::<Params>().init.continental_thickness_km as f32;
    let mut writes: Vec<(usize, f32, Vec<u32>)> = Vec::new();
    {
        let crust = world.resource::<Crust>();
        let mesh = world.resource::<SphereMesh>();
        let mut elevation = crust.elevation_km.clone();
        let mut crust_type = crust.crust_type.clone();
        for comp in &trapped {
            // Fill from the shore inward with the mean elevation of continental neighbours.
            let mut remaining: Vec<usize> = comp.clone();
            while !remaining.is_empty() {
                let mut next = Vec::new();
                let mut filled = Vec::new();
                for &u in &remaining {
                    let (mut sum, mut cnt) = (0.0f64, 0u32);
                    for &v in mesh.neighbors_of(u) {
                        if crust_type[v as usize] == CrustType::Continental {
                            sum += elevation[v as usize] as f64;
                            cnt += 1;
                        }
                    }
                    if cnt > 0 {
                        filled.push((u, (sum / cnt as f64) as f32));
                    } else {
                        next.push(u);
                    }
                }
                if filled.is_empty() {
                    break;
                }
                for (u, z) in filled {
                    elevation[u] = z;
                    crust_type[u] = CrustType::Continental;
                    writes.push((u, z, mesh.neighbors_of(u).to_vec()));
                }
                remaining = next;
            }
        }
    }
    use crate::gpu::FieldMask;
    crate::gpu::write_crust_fields_or_record(
        world,
        FieldMask::ELEVATION | FieldMask::CRUST_TYPE | FieldMask::THICKNESS,
        |crust| {
            // In the same order: each welded sample takes the mean thickness of its continental
            // neighbours (those welded before it included), so the weld leaves no hole in a
            // thickened crust (with isostasy on, a thin spot would stand kilometres low).
            for (u, z, nbrs) in &writes {
                let (mut sum, mut cnt) = (0.0f64, 0u32);
                for &v in nbrs {
                    if crust.crust_type[v as usize] == CrustType::Continental {
                        sum += crust.thickness_km[v as usize] as f64;
                        cnt += 1;
                    }
                }
                crust.elevation_km[*u] = *z;
                crust.crust_type[*u] = CrustType::Continental;
                crust.thickness_km[*u] = if cnt > 0 {
                    (sum / cnt as f64) as f32
                } else {
                    fallback
                };
            }
        },
    );
}

/// Rebuilds the terranes: connected continental regions within each plate, and with
/// `collision.docking` the island arcs (connected regions of oceanic crust at least
/// `collision.arc_min_thickness_km` thick), as entities and as the per-sample [`TerraneField`].
/// An arc terrane is known by its samples' crust type (oceanic).
pub fn build_terranes(world: &mut World) {
    let _timer = crate::systems::DebugTimer::new("build_terranes");
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    let params = world.resource::<Params>();
    let arc_min = if params.collision.docking {
        params.collision.arc_min_thickness_km as f32
    } else {
        f32::INFINITY
    };
    // The kind of terrane a sample belongs to: 1 continental, 2 arc, 0 none.
    let kind = |i: usize| -> u8 {
        match crust.crust_type[i] {
            CrustType::Continental => 1,
            CrustType::Oceanic if crust.thickness_km[i] >= arc_min => 2,
            CrustType::Oceanic => 0,
        }
    };
    let n = mesh.len();
    let mut field = TerraneField {
        terrane: vec![NONE; n],
        ..Default::default()
    };
    let mut terranes = Vec::new();
    let mut stack = Vec::new();
    for s in 0..n {
        let ks = kind(s);
        if field.terrane[s] != NONE || ks == 0 {
            continue;
        }
        let t = field.area_km2.len() as u32;
        let plate = crust.plate[s];
        field.terrane[s] = t;
        stack.push(s as u32);
        let (mut area, mut centroid, mut count) = (0.0, DVec3::ZERO, 0u32);
        while let Some(u) = stack.pop() {
            let u = u as usize;
            area += mesh.area_km2[u];
            centroid += mesh.positions[u] * mesh.area_km2[u];
            count += 1;
            for &v in mesh.neighbors_of(u) {
                let v = v as usize;
                if field.terrane[v] == NONE && kind(v) == ks && crust.plate[v] == plate {
                    field.terrane[v] = t;
                    stack.push(v as u32);
                }
            }
        }
        let centroid = centroid.try_normalize().unwrap_or(mesh.positions[s]);
        field.area_km2.push(area);
        field.plate.push(plate);
        field.centroid.push(centroid);
        terranes.push(Terrane {
            index: t,
            plate: PlateId(plate),
            area_km2: area,
            centroid,
            samples: count,
        });
    }
    world.insert_resource(field);
    let old: Vec<Entity> = world
        .query_filtered::<Entity, With<Terrane>>()
        .iter(world)
        .collect();
    for e in old {
        world.despawn(e);
    }
    world.spawn_batch(terranes);
}
