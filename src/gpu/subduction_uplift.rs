//! Host side of `shaders/subduction_uplift.wgsl`: subduction uplift, Andean orogeny, fold
//! directions and trenches on the resident crust buffers. The CPU reference is
//! [`subduction_uplift_cpu`](crate::systems::convergence::subduction::subduction_uplift_cpu) (the function the CPU backend runs, in
//! `src/systems/convergence/subduction.rs`).
//!
//! The per-sample convergence field goes up once per resampling (when its change tick moves);
//! per step only the front-point table ([`FrontGpu`], 32 bytes a point) and the uniforms do.
//! Per-point factors are computed here in f64 exactly as the CPU does (the fold increment is
//! then bit-identical); the distance transfer f(d) is evaluated on the device in f32.

use bevy_ecs::change_detection::Tick;

use crate::gpu::{
    FieldMask, GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};
use crate::resources::convergence::NONE;
use crate::resources::{ConvergenceField, Crust, FrontPoints, Params};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/subduction_uplift.wgsl");

/// The constants of one subduction-uplift step (from the parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpliftConstants {
    /// r_s: subduction distance, km.
    pub rs: f64,
    /// r_c: control distance, km.
    pub rc: f64,
    /// δt, My.
    pub dt: f64,
    /// u0, km/My.
    pub u0: f64,
    /// v0: maximum plate speed, km/My.
    pub v0: f64,
    /// z_t: trench elevation, km.
    pub z_t: f64,
    /// z_c: maximum continental elevation, km.
    pub z_c: f64,
    /// z_a: abyssal elevation, km.
    pub z_a: f64,
    /// β: fold weight.
    pub beta: f64,
    /// Trench width, km.
    pub wt: f64,
    /// Trench deepening rate per step.
    pub rate: f64,
    /// z_r: ridge elevation, km.
    pub z_r: f64,
    /// Continental crust thickening per km of uplift, km/km: 1/(1 − ρ_c/ρ_m), so that the uplift
    /// is the surface rise before erosion once isostasy compensates the new crust.
    pub thickening: f64,
    /// Thickest continental crust the uplift makes, km.
    pub max_thickness_km: f64,
    /// Oceanic crust thickening per km of uplift: 1/((ρ_m − ρ_s)/(ρ_m − ρ_w)), the inverse of the
    /// sea floor's rise per km of crust above the normal oceanic thickness.
    pub oceanic_thickening: f64,
    /// Thickest oceanic crust the uplift makes (island arcs), km.
    pub max_oceanic_thickness_km: f64,
    /// Isostatic relief ([`ReliefMode`](crate::resources::ReliefMode)): the uplift thickens the
    /// crust and leaves the elevation (and the trench) to isostasy; otherwise it raises the
    /// elevation and cuts the trench, as the paper does, and the thickness stays.
    pub isostatic: bool,
}

impl UpliftConstants {
    /// The same constants for isostatic relief (`true`) or the paper's (`false`).
    pub fn with_isostasy(self, isostatic: bool) -> Self {
        Self { isostatic, ..self }
    }

    /// The constants for `params` (the paper's relief; see [`Self::with_isostasy`]).
    pub fn new(params: &Params) -> Self {
        let s = &params.subduction;
        Self {
            rs: s.distance_km,
            rc: s.control_distance_km,
            dt: params.time.time_step_my,
            u0: s.uplift_mm_per_yr,
            v0: params.plates.max_speed_mm_per_yr,
            z_t: params.ocean.trench_elevation_km,
            z_c: params.continent.max_elevation_km,
            z_a: params.ocean.abyssal_elevation_km,
            beta: s.fold_weight,
            wt: s.trench_width_km,
            rate: s.trench_rate,
            z_r: params.ocean.ridge_elevation_km,
            thickening: 1.0 / crate::resources::params::dry_isostatic_gain(params),
            max_thickness_km: params.isostasy.max_thickness_km,
            oceanic_thickening: 1.0 / crate::resources::params::oceanic_load_gain(params),
            max_oceanic_thickness_km: params.isostasy.max_oceanic_thickness_km,
            isostatic: false,
        }
    }
}

/// Uniforms of one uplift step. Keep in sync with `UpliftUniforms` in
/// shaders/subduction_uplift.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct UpliftUniforms {
    /// r_s, km.
    pub distance_km: f32,
    /// r_c / r_s.
    pub control_ratio: f32,
    /// r_s³ over the denominator of the distance transfer (0 when it vanishes).
    pub transfer_inv_den: f32,
    /// δt, My.
    pub dt_my: f32,
    /// z_t, km.
    pub trench_elevation_km: f32,
    /// z_c, km.
    pub max_elevation_km: f32,
    /// z_a, km.
    pub abyssal_elevation_km: f32,
    /// z_r, km.
    pub ridge_elevation_km: f32,
    /// Trench width, km.
    pub trench_width_km: f32,
    /// Trench deepening rate per step.
    pub trench_rate: f32,
    /// Samples.
    pub count: u32,
    /// Threads (words of four samples) per dispatch row.
    pub row_stride: u32,
    /// Continental crust thickening per km of uplift.
    pub thickening: f32,
    /// Thickest continental crust the uplift makes, km.
    pub max_thickness_km: f32,
    /// Oceanic crust thickening per km of uplift.
    pub oceanic_thickening: f32,
    /// Thickest oceanic crust the uplift makes, km.
    pub max_oceanic_thickness_km: f32,
    /// 1: isostatic relief (thicken only), 0: the paper's (raise the elevation, cut trenches).
    pub isostatic: u32,
    /// Padding to 16 bytes.
    pub _pad: [u32; 3],
}

impl UpliftUniforms {
    /// The uniforms for `k` over `count` samples.
    pub fn new(k: &UpliftConstants, count: u32) -> Self {
        let (rs, rc) = (k.rs, k.rc);
        let den = (rs.powi(3) - rc.powi(3)) / 6.0 + (rc * rc * rs - rs * rs * rc) / 2.0;
        let inv = if den.abs() < 1e-12 {
            0.0
        } else {
            rs.powi(3) / den
        };
        Self {
            distance_km: rs as f32,
            control_ratio: if rs > 0.0 { (rc / rs) as f32 } else { 0.0 },
            transfer_inv_den: inv as f32,
            dt_my: k.dt as f32,
            trench_elevation_km: k.z_t as f32,
            max_elevation_km: k.z_c as f32,
            abyssal_elevation_km: k.z_a as f32,
            ridge_elevation_km: k.z_r as f32,
            trench_width_km: k.wt as f32,
            trench_rate: k.rate as f32,
            count,
            row_stride: ROW_STRIDE,
            thickening: k.thickening as f32,
            max_thickness_km: k.max_thickness_km as f32,
            oceanic_thickening: k.oceanic_thickening as f32,
            max_oceanic_thickness_km: k.max_oceanic_thickness_km as f32,
            isostatic: u32::from(k.isostatic),
            _pad: [0; 3],
        }
    }
}

/// One front point as the kernel reads it. Keep in sync with `FrontGpu` in
/// shaders/subduction_uplift.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FrontGpu {
    /// β·δt·(relative velocity), x, overriding frame (added to the fold direction).
    pub fold_inc_x: f32,
    /// Same, y.
    pub fold_inc_y: f32,
    /// Same, z.
    pub fold_inc_z: f32,
    /// u0·g(v)·h(z̃), km/My (times f(d) gives the uplift rate).
    pub uplift_scale_km_per_my: f32,
    /// Convergence since the last resampling, km.
    pub converged_km: f32,
    /// 1 while subducting crust is under the point.
    pub is_active: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
}

/// The front-point table for this step.
pub fn front_table(k: &UpliftConstants, fp: &FrontPoints) -> Vec<FrontGpu> {
    (0..fp.len())
        .map(|i| {
            let rel = fp.relative_velocity[i];
            let zs = fp.subducting_elevation_km[i] as f64;
            let zn = ((zs - k.z_t) / (k.z_c - k.z_t)).clamp(0.0, 1.0);
            let f = rel * (k.beta * k.dt);
            FrontGpu {
                fold_inc_x: f.x as f32,
                fold_inc_y: f.y as f32,
                fold_inc_z: f.z as f32,
                uplift_scale_km_per_my: (k.u0 * (rel.length() / k.v0).min(1.0) * zn * zn) as f32,
                converged_km: fp.converged_km[i],
                is_active: u32::from(fp.active[i]),
                _pad0: 0,
                _pad1: 0,
            }
        })
        .collect()
}

/// Pipeline and buffers of the kernel.
pub(crate) struct UpliftKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    /// Interleaved convergence field and its length.
    field: Option<(wgpu::Buffer, usize)>,
    field_synced: Option<Tick>,
    /// Front table and its capacity in points.
    fronts: Option<(wgpu::Buffer, usize)>,
    bind_group: Option<wgpu::BindGroup>,
}

impl Kernel for UpliftKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, "subduction_uplift", WGSL),
            uniforms: uniform_buffer(
                device,
                "subduction_uplift uniforms",
                std::mem::size_of::<UpliftUniforms>(),
            ),
            field: None,
            field_synced: None,
            fronts: None,
            bind_group: None,
        }
    }
    fn forget_bind_groups(&mut self) {
        self.bind_group = None;
    }
}

const KERNEL: &str = "subduction_uplift";

/// One uplift step on the resident crust buffers (call [`GpuContext::sync_crust`] first).
/// `field` is uploaded unless the device copy is in sync with its change tick `field_tick`
/// (`None` forces the upload).
pub fn subduction_uplift_dispatch(
    ctx: &mut GpuContext,
    k: &UpliftConstants,
    fp: &FrontPoints,
    field: &ConvergenceField,
    field_tick: Option<Tick>,
) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, kern: &mut UpliftKernel| {
        let Some(n) = ctx.crust_buffers().map(|b| b.len) else {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: "the crust is not on the device".into(),
            });
        };
        if field.overriding_point.len() != n
            || field.overriding_distance_km.len() != n
            || field.subducting_point.len() != n
            || field.subducting_distance_km.len() != n
        {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: format!("convergence field does not have {n} samples"),
            });
        }
        if let Some(bad) = field
            .overriding_point
            .iter()
            .chain(&field.subducting_point)
            .find(|&&p| p != NONE && p as usize >= fp.len())
        {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: format!("front point {bad} out of range ({} points)", fp.len()),
            });
        }
        // Convergence field: once per resampling.
        if kern.field.as_ref().is_none_or(|f| f.1 != n) {
            let buf = ctx.storage_buffer("convergence field (od, op, sd, sp)", 16 * n);
            kern.field = Some((buf, n));
            kern.field_synced = None;
            kern.bind_group = None;
        }
        if field_tick.is_none() || kern.field_synced != field_tick {
            let packed: Vec<[u32; 4]> = (0..n)
                .map(|i| {
                    [
                        field.overriding_distance_km[i].to_bits(),
                        field.overriding_point[i],
                        field.subducting_distance_km[i].to_bits(),
                        field.subducting_point[i],
                    ]
                })
                .collect();
            if let Some((buf, _)) = kern.field.clone() {
                ctx.upload(&buf, bytemuck::cast_slice(&packed));
            }
            kern.field_synced = field_tick;
        }
        // Front table: every step.
        let table = front_table(k, fp);
        if kern
            .fronts
            .as_ref()
            .is_none_or(|f| f.1 < table.len().max(1))
        {
            let cap = table.len().max(1).next_power_of_two();
            let buf = ctx.storage_buffer("front points", cap * std::mem::size_of::<FrontGpu>());
            kern.fronts = Some((buf, cap));
            kern.bind_group = None;
        }
        if let Some((buf, _)) = kern.fronts.clone() {
            ctx.upload(&buf, bytemuck::cast_slice(&table));
        }
        if kern.bind_group.is_none() {
            let (Some(b), Some((fb, _)), Some((frb, _))) = (
                ctx.crust_buffers(),
                kern.field.as_ref(),
                kern.fronts.as_ref(),
            ) else {
                return Err(GpuError::Kernel {
                    kernel: KERNEL,
                    message: "buffers missing".into(),
                });
            };
            let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("subduction_uplift bindings"),
                layout: &kern.pipeline.get_bind_group_layout(0),
                entries: &[
                    entry(0, &kern.uniforms),
                    entry(1, &b.elevation_km),
                    entry(2, &b.orogeny),
                    entry(3, &b.orogeny_age_my),
                    entry(4, &b.fold_dir),
                    entry(5, &b.crust_type),
                    entry(6, fb),
                    entry(7, frb),
                    entry(8, &b.thickness_km),
                ],
            });
            kern.bind_group = Some(bg);
        }
        let u = UpliftUniforms::new(k, n as u32);
        let (pipeline, uniforms) = (kern.pipeline.clone(), kern.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        let Some(bg) = kern.bind_group.clone() else {
            return Ok(());
        };
        ctx.dispatch(KERNEL, &pipeline, &bg, (n as u32).div_ceil(4))
    })
}

/// The fields the kernel writes on the device: elevation, orogeny, orogeny age, fold direction.
pub const WRITES: FieldMask = crate::gpu::collision_uplift::WRITES;

/// Reads the fields the kernel writes ([`WRITES`]) back into `crust` (a [`GpuContext::pull`]
/// of them; the simulation itself leaves them on the device and lets readers pull).
pub fn read_back(ctx: &mut GpuContext, crust: &mut Crust) -> Result<(), GpuError> {
    ctx.pull_written(WRITES, crust)
}
