//! Host side of `shaders/collision_uplift.wgsl`: the collision surge around each sutured
//! terrane (uplift of continental crust, Himalayan orogeny, fold directions away from the
//! terrane) on the resident crust buffers. The CPU reference is [`collision_uplift_cpu`](crate::systems::convergence::collision::collision_uplift_cpu) (the
//! function the CPU backend runs, in `src/systems/convergence/collision.rs`).
//!
//! The distance of each sample to the terrane (a graph search through the terrane's new plate,
//! `propagate_nearest`) stays on the CPU; per surge, the distances go up (4 bytes a sample) with
//! the uniforms, and the reference positions go up once per mesh (12 bytes a sample). The
//! surges of one resampling run one after the other on the device, in the CPU's order, and the
//! fields they write ([`WRITES`]) stay on the device, marked newer there
//! ([`GpuContext::note_device_write`]); the CPU systems after them pull what they read.

use glam::DVec3;

use crate::gpu::{
    FieldMask, GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};
use crate::resources::Crust;

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/collision_uplift.wgsl");

/// One sutured terrane's collision surge (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollisionSurge {
    /// r: radius of the surge, km.
    pub radius_km: f64,
    /// Δz₀: uplift at the terrane, km.
    pub peak_km: f64,
    /// Planet radius, km.
    pub planet_radius_km: f64,
    /// z_c: elevations are capped here, km.
    pub max_elevation_km: f64,
    /// The terrane's centroid (world frame, unit vector); fold directions point away from it.
    pub centroid: DVec3,
    /// Crust thickening per km of uplift, km/km (1/(1 − ρ_c/ρ_m)).
    pub thickening: f64,
    /// Thickest crust the surge makes, km.
    pub max_thickness_km: f64,
    /// Isostatic relief: the surge thickens the crust and leaves the elevation to isostasy;
    /// otherwise it raises the elevation (the paper's) and the thickness stays.
    pub isostatic: bool,
}

const KERNEL: &str = "collision_uplift";

/// Uniforms of one surge. Keep in sync with `CollisionUniforms` in
/// shaders/collision_uplift.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CollisionUniforms {
    /// Terrane centroid, x (world frame).
    pub centroid_x: f32,
    /// Terrane centroid, y.
    pub centroid_y: f32,
    /// Terrane centroid, z.
    pub centroid_z: f32,
    /// Δz₀, km.
    pub peak_km: f32,
    /// Planet radius over r (turns a distance in radians into d/r); 0 when r = 0.
    pub dist_scale: f32,
    /// z_c, km.
    pub max_elevation_km: f32,
    /// Samples.
    pub count: u32,
    /// Threads (words of four samples) per dispatch row.
    pub row_stride: u32,
    /// Crust thickening per km of uplift.
    pub thickening: f32,
    /// Thickest crust the surge makes, km.
    pub max_thickness_km: f32,
    /// 1: isostatic relief (thicken only), 0: the paper's (raise the elevation).
    pub isostatic: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

impl CollisionUniforms {
    /// The uniforms for surge `s` over `count` samples.
    pub fn new(s: &CollisionSurge, count: u32) -> Self {
        Self {
            centroid_x: s.centroid.x as f32,
            centroid_y: s.centroid.y as f32,
            centroid_z: s.centroid.z as f32,
            peak_km: s.peak_km as f32,
            dist_scale: if s.radius_km > 0.0 {
                (s.planet_radius_km / s.radius_km) as f32
            } else {
                0.0
            },
            max_elevation_km: s.max_elevation_km as f32,
            count,
            row_stride: ROW_STRIDE,
            thickening: s.thickening as f32,
            max_thickness_km: s.max_thickness_km as f32,
            isostatic: u32::from(s.isostatic),
            _pad: 0,
        }
    }
}

/// Pipeline and buffers of the kernel.
pub(crate) struct CollisionKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    /// Reference positions (f32) and the mesh they belong to: sample count and the bits of
    /// the first and last positions.
    positions: Option<(wgpu::Buffer, (usize, [u64; 2]))>,
    /// Distances of one surge and their length in samples.
    dist: Option<(wgpu::Buffer, usize)>,
    bind_group: Option<wgpu::BindGroup>,
}

impl Kernel for CollisionKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, KERNEL, WGSL),
            uniforms: uniform_buffer(
                device,
                "collision_uplift uniforms",
                std::mem::size_of::<CollisionUniforms>(),
            ),
            positions: None,
            dist: None,
            bind_group: None,
        }
    }
    fn forget_bind_groups(&mut self) {
        self.bind_group = None;
    }
}

fn mesh_key(positions: &[DVec3]) -> (usize, [u64; 2]) {
    let bits = |p: Option<&DVec3>| p.map_or(0, |p| p.x.to_bits() ^ p.y.to_bits().rotate_left(21));
    (
        positions.len(),
        [bits(positions.first()), bits(positions.last())],
    )
}

fn fail(message: String) -> GpuError {
    GpuError::Kernel {
        kernel: KERNEL,
        message,
    }
}

/// Applies the surges in order on the resident crust buffers (call
/// [`GpuContext::sync_crust`] first). Each surge comes with its distances (radians, one per
/// sample, infinite where it does not reach); `positions` are the reference positions. Read the
/// result with [`read_back`].
pub fn collision_uplift_gpu(
    ctx: &mut GpuContext,
    positions: &[DVec3],
    surges: &[(CollisionSurge, Vec<f32>)],
) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, k: &mut CollisionKernel| {
        let Some(n) = ctx.crust_buffers().map(|b| b.len) else {
            return Err(fail("the crust is not on the device".into()));
        };
        if positions.len() != n {
            return Err(fail(format!(
                "{} positions for a crust of {n} samples",
                positions.len()
            )));
        }
        if let Some((_, d)) = surges.iter().find(|(_, d)| d.len() != n) {
            return Err(fail(format!(
                "{} distances for a crust of {n} samples",
                d.len()
            )));
        }
        if surges.is_empty() {
            return Ok(());
        }
        let key = mesh_key(positions);
        if k.positions.as_ref().is_none_or(|p| p.1 != key) {
            let flat: Vec<f32> = positions
                .iter()
                .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect();
            let buf = ctx.storage_buffer("collision_uplift positions", 4 * flat.len());
            ctx.upload(&buf, bytemuck::cast_slice(&flat));
            k.positions = Some((buf, key));
            k.bind_group = None;
        }
        if k.dist.as_ref().is_none_or(|d| d.1 != n) {
            let buf = ctx.storage_buffer("collision_uplift distances", 4 * n);
            k.dist = Some((buf, n));
            k.bind_group = None;
        }
        if k.bind_group.is_none() {
            let (Some(b), Some((pb, _)), Some((db, _))) =
                (ctx.crust_buffers(), k.positions.as_ref(), k.dist.as_ref())
            else {
                return Err(fail("buffers missing".into()));
            };
            let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("collision_uplift bindings"),
                layout: &k.pipeline.get_bind_group_layout(0),
                entries: &[
                    entry(0, &k.uniforms),
                    entry(1, &b.elevation_km),
                    entry(2, &b.orogeny),
                    entry(3, &b.orogeny_age_my),
                    entry(4, &b.fold_dir),
                    entry(5, &b.crust_type),
                    entry(6, pb),
                    entry(7, db),
                    entry(8, &b.thickness_km),
                ],
            });
            k.bind_group = Some(bg);
        }
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        let (Some(bg), Some((dist, _))) = (k.bind_group.clone(), k.dist.clone()) else {
            return Err(fail("buffers missing".into()));
        };
        // Writes to the distances and uniforms are ordered before the next submission, so one
        // buffer of each serves every surge.
        for (s, d) in surges {
            let u = CollisionUniforms::new(s, n as u32);
            ctx.upload(&uniforms, bytemuck::bytes_of(&u));
            ctx.upload(&dist, bytemuck::cast_slice(d));
            ctx.dispatch(KERNEL, &pipeline, &bg, (n as u32).div_ceil(4))?;
            ctx.traffic.collision_surges += 1;
        }
        Ok(())
    })
}

/// The fields the kernel writes on the device: elevation, thickness, orogeny, orogeny age, fold
/// direction.
pub const WRITES: FieldMask = FieldMask(
    FieldMask::ELEVATION.0
        | FieldMask::THICKNESS.0
        | FieldMask::OROGENY.0
        | FieldMask::OROGENY_AGE.0
        | FieldMask::FOLD_DIR.0,
);

/// The fields the kernel writes for isostatic relief (thickness) or the paper's (elevation),
/// with the orogeny and fold fields.
pub fn writes(isostatic: bool) -> FieldMask {
    let relief = if isostatic {
        FieldMask::THICKNESS
    } else {
        FieldMask::ELEVATION
    };
    FieldMask(relief.0 | FieldMask::OROGENY.0 | FieldMask::OROGENY_AGE.0 | FieldMask::FOLD_DIR.0)
}

/// Reads the fields the kernel writes ([`WRITES`]) back into `crust` (a [`GpuContext::pull`]
/// of them; the simulation itself leaves them on the device and lets readers pull).
pub fn read_back(ctx: &mut GpuContext, crust: &mut Crust) -> Result<(), GpuError> {
    ctx.pull_written(WRITES, crust)
}
