//! Host side of `shaders/resample_interpolate.wgsl`: the interpolation of a resampling (every
//! field of the old crust at each sample's located source into the new crust). The CPU
//! reference is [`resample_interpolate_cpu`](fn@crate::systems::resample::interpolate) (`interpolate` in `src/systems/resample/interpolate.rs`, the
//! function the CPU backend runs).
//!
//! What crosses the bus: once per mesh, the reference positions and triangles (about 36 bytes a
//! sample); per resampling, the located sources (32 bytes a sample) and the plate table (64
//! bytes a plate, plus 4 bytes per plate id for the frame group of each id); back, the new crust
//! (46 bytes a sample). The old crust is the resident one ([`crate::gpu::CrustBuffers`], all 46
//! bytes a sample since stage 3 of docs/gpu-residency.md), copied on the device into the layout
//! the kernel reads; call [`GpuContext::sync_crust`] with the old crust first. Which plates moved
//! exactly alike (the CPU compares their f64 rotations) is decided on the host: each plate gets
//! the slot of the first plate with the same rotation as its frame group, and the kernel
//! compares the groups of the plate ids.
//!
//! The gaps (samples no plate covers), their nearest plates (a graph search from the covered
//! samples, not per sample) and the gap filling stay on the CPU.

use glam::DVec3;

use crate::geometry::SphereMesh;
use crate::gpu::resample_locate::SampleSource;
use crate::gpu::{
    GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};
use crate::resources::{Crust, CrustType, Orogeny, PlateTable};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/resample_interpolate.wgsl");

const KERNEL: &str = "resample_interpolate";

/// Uniforms of one interpolation. Keep in sync with `InterpolateUniforms` in
/// shaders/resample_interpolate.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct InterpolateUniforms {
    /// Samples.
    pub count: u32,
    /// Threads (words of four samples) per dispatch row.
    pub row_stride: u32,
    /// Words of a packed u8 field: ceil(count / 4).
    pub packed_words: u32,
    /// Word offset, in the plate table, of the frame group of each plate id.
    pub ids_at: u32,
    /// Entries of that table (the largest plate id plus one).
    pub id_count: u32,
    /// Padding.
    pub _pad: [u32; 3],
}

/// Pipeline and the resident mesh (positions and triangles).
pub(crate) struct InterpolateKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    mesh: Option<(wgpu::Buffer, (usize, usize, u64))>,
}

impl Kernel for InterpolateKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, KERNEL, WGSL),
            uniforms: uniform_buffer(
                device,
                "resample_interpolate uniforms",
                std::mem::size_of::<InterpolateUniforms>(),
            ),
            mesh: None,
        }
    }
}

fn fail(message: String) -> GpuError {
    GpuError::Kernel {
        kernel: KERNEL,
        message,
    }
}

fn check_size(what: &str, bytes: usize, limit: u64) -> Result<(), GpuError> {
    if bytes as u64 > limit {
        return Err(GpuError::TooLarge(format!(
            "{KERNEL}: {what} needs {bytes} bytes, more than the device's storage binding limit \
             of {limit} bytes"
        )));
    }
    Ok(())
}

/// The frame group of each slot: the first slot whose plate has exactly the same rotation
/// (world ← plate), as the CPU's test `world_from_plate == world_from_plate`.
fn frame_groups(table: &PlateTable) -> Vec<u32> {
    (0..table.plates.len())
        .map(|s| {
            let m = table.plates[s].world_from_plate;
            (0..=s)
                .find(|&k| table.plates[k].world_from_plate == m)
                .unwrap_or(s) as u32
        })
        .collect()
}

/// Interpolates every field of `old` at `sources` into `next` on the device: same semantics as
/// [`resample_interpolate_cpu`](fn@crate::systems::resample::interpolate), in f32 (see docs/gpu.md for the tolerances). The kernel reads
/// the old crust from the resident buffers, which must hold `old` (call
/// [`GpuContext::sync_crust`] first; the host copy of `old` may be stale in the fields the
/// device holds newer, it is only used for its size).
pub fn resample_interpolate_gpu(
    ctx: &mut GpuContext,
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    sources: &[SampleSource],
    next: &mut Crust,
) -> Result<(), GpuError> {
    interpolate_with(ctx, mesh, old, table, sources, false, next)
}

/// [`resample_interpolate_gpu`] reading the sources from the device: `sources` must be the ones
/// the last [`resample_locate_gpu`](crate::systems::resample::resample_locate_gpu) returned, whose output (with
/// the rechecked samples written back) is still on the device; only the checks read the host
/// copy. Nothing of the sources goes up. An error if the device holds no complete location.
pub fn resample_interpolate_gpu_located(
    ctx: &mut GpuContext,
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    sources: &[SampleSource],
    next: &mut Crust,
) -> Result<(), GpuError> {
    interpolate_with(ctx, mesh, old, table, sources, true, next)
}

fn interpolate_with(
    ctx: &mut GpuContext,
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    sources: &[SampleSource],
    located: bool,
    next: &mut Crust,
) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, k: &mut InterpolateKernel| {
        let n = mesh.len();
        if old.len() != n || sources.len() != n {
            return Err(fail(format!(
                "inputs of different sizes: mesh {n}, old crust {}, sources {}",
                old.len(),
                sources.len()
            )));
        }
        if let Some((j, s)) = sources.iter().enumerate().find(|(_, s)| {
            !s.is_gap()
                && (s.slot as usize >= table.plates.len()
                    || s.triangle as usize >= mesh.triangles.len())
        }) {
            return Err(fail(format!(
                "source of sample {j} out of range (slot {}, triangle {})",
                s.slot, s.triangle
            )));
        }
        if n == 0 {
            next.resize(0);
            return Ok(());
        }
        let nw = n.div_ceil(4);
        let limit = ctx.device.limits().max_storage_buffer_binding_size;
        let old_words = 11 * n + 2 * nw;
        check_size("the old crust", 4 * old_words, limit)?;
        check_size("the mesh", 12 * n + 12 * mesh.triangles.len(), limit)?;
        check_size("the sources", 32 * n, limit)?;
        // The mesh: once per mesh.
        let key = (
            n,
            mesh.triangles.len(),
            mesh.positions.first().map_or(0, |p: &DVec3| p.x.to_bits()),
        );
        if k.mesh.as_ref().is_none_or(|m| m.1 != key) {
            let mut words: Vec<u32> = Vec::with_capacity(3 * n + 3 * mesh.triangles.len());
            words.extend(
                mesh.positions
                    .iter()
                    .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32].map(f32::to_bits)),
            );
            words.extend_from_slice(bytemuck::cast_slice(&mesh.triangles));
            let buf = ctx.storage_buffer("resample_interpolate mesh", 4 * words.len());
            ctx.upload(&buf, bytemuck::cast_slice(&words));
            k.mesh = Some((buf, key));
        }
        // The plate table with frame groups, then the frame group of every plate id (the old
        // crust holds plate ids; the kernel maps them through this table).
        let groups = frame_groups(table);
        let mut plate_words: Vec<u32> = Vec::with_capacity(16 * table.plates.len().max(1));
        for (s, p) in table.plates.iter().enumerate() {
            let m = p.world_from_plate;
            plate_words.extend_from_slice(&[groups[s], 0, 0, 0]);
            for i in 0..3 {
                let row = [m.x_axis[i], m.y_axis[i], m.z_axis[i]].map(|x| (x as f32).to_bits());
                plate_words.extend_from_slice(&row);
                plate_words.push(0);
            }
        }
        let ids_at = plate_words.len();
        let id_count = table
            .plates
            .iter()
            .map(|p| p.id as usize + 1)
            .max()
            .unwrap_or(0);
        check_size("the plate table", 4 * (ids_at + id_count), limit)?;
        plate_words
            .extend((0..id_count).map(|id| table.slot(id as u32).map_or(u32::MAX, |s| groups[s])));
        if plate_words.is_empty() {
            plate_words.resize(16, 0);
        }
        // The old crust is the resident one (stage 3 of docs/gpu-residency.md): copied on the
        // device into the layout the kernel reads, nothing of it crosses the bus.
        let Some(b) = ctx.crust_buffers().filter(|b| b.len == n) else {
            return Err(fail(
                "the old crust is not on the device (call sync_crust first)".into(),
            ));
        };
        let old_buf = ctx.storage_buffer("resample_interpolate old crust", 4 * old_words);
        {
            let (n4, nw4) = (4 * n as u64, 4 * nw as u64);
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("resample_interpolate old crust"),
                });
            let mut at = 0;
            for (field, bytes) in [
                (&b.elevation_km, n4),
                (&b.thickness_km, n4),
                (&b.age_my, n4),
                (&b.orogeny_age_my, n4),
                (&b.ridge_dir, 3 * n4),
                (&b.fold_dir, 3 * n4),
                (&b.crust_type, nw4),
                (&b.orogeny, nw4),
                (&b.plate, n4),
            ] {
                enc.copy_buffer_to_buffer(field, 0, &old_buf, at, bytes);
                at += bytes;
            }
            ctx.queue.submit([enc.finish()]);
        }
        ctx.check(KERNEL)?;
        let src_buf = if located {
            match crate::gpu::resample_locate::located_output(ctx, n) {
                Some(b) => b,
                None => {
                    return Err(fail(
                        "no complete location of this size on the device".into(),
                    ));
                }
            }
        } else {
            let source_words: Vec<u32> = sources
                .iter()
                .flat_map(crate::gpu::sources_patch::source_words)
                .collect();
            let buf = ctx.storage_buffer("resample_interpolate sources", 4 * source_words.len());
            ctx.upload(&buf, bytemuck::cast_slice(&source_words));
            buf
        };
        let plate_buf = ctx.storage_buffer("resample_interpolate plates", 4 * plate_words.len());
        ctx.upload(&plate_buf, bytemuck::cast_slice(&plate_words));
        let next_buf = ctx.storage_buffer("resample_interpolate next crust", 4 * old_words);
        let Some((mesh_buf, _)) = k.mesh.as_ref() else {
            return Err(fail("the mesh is not on the device".into()));
        };
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("resample_interpolate bindings"),
            layout: &k.pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, &k.uniforms),
                entry(1, &src_buf),
                entry(2, &plate_buf),
                entry(3, mesh_buf),
                entry(4, &old_buf),
                entry(5, &next_buf),
            ],
        });
        let u = InterpolateUniforms {
            count: n as u32,
            row_stride: ROW_STRIDE,
            packed_words: nw as u32,
            ids_at: ids_at as u32,
            id_count: id_count as u32,
            _pad: [0; 3],
        };
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        ctx.dispatch(KERNEL, &pipeline, &bind_group, nw as u32)?;
        // Poisoned before the readback: a copy that does not happen cannot pass.
        let mut out = vec![u32::MAX; old_words];
        ctx.download(KERNEL, &next_buf, bytemuck::cast_slice_mut(&mut out))?;
        next.resize(n);
        let f32s = |k: usize| out[k * n..(k + 1) * n].iter().map(|&b| f32::from_bits(b));
        next.elevation_km
            .iter_mut()
            .zip(f32s(0))
            .for_each(|(a, b)| *a = b);
        next.thickness_km
            .iter_mut()
            .zip(f32s(1))
            .for_each(|(a, b)| *a = b);
        next.age_my
            .iter_mut()
            .zip(f32s(2))
            .for_each(|(a, b)| *a = b);
        next.orogeny_age_my
            .iter_mut()
            .zip(f32s(3))
            .for_each(|(a, b)| *a = b);
        for (field, at) in [(&mut next.ridge_dir, 4 * n), (&mut next.fold_dir, 7 * n)] {
            for (d, c) in field.iter_mut().zip(out[at..at + 3 * n].chunks_exact(3)) {
                *d = [c[0], c[1], c[2]].map(f32::from_bits);
            }
        }
        let byte = |at: usize, i: usize| (out[at + i / 4] >> (8 * (i % 4))) as u8;
        for i in 0..n {
            next.crust_type[i] = match byte(10 * n, i) {
                0 => CrustType::Oceanic,
                1 => CrustType::Continental,
                b => return Err(fail(format!("crust type code {b} at sample {i}"))),
            };
            next.orogeny[i] = match byte(10 * n + nw, i) {
                0 => Orogeny::None,
                1 => Orogeny::Andean,
                2 => Orogeny::Himalayan,
                b => return Err(fail(format!("orogeny code {b} at sample {i}"))),
            };
        }
        next.plate
            .copy_from_slice(&out[10 * n + 2 * nw..11 * n + 2 * nw]);
        ctx.traffic.interpolations += 1;
        Ok(())
    })
}
