//! Host side of `shaders/isostasy.wgsl`: the per-sample combine of the isostasy phenomenon
//! (continental Airy columns held by the regional response, ocean floor from the age–depth law
//! with its load, the flexure and the trench) written into the resident elevation buffer. The
//! CPU reference is [`isostasy_cpu`](crate::systems::relief::isostasy::isostasy_cpu) (the
//! function the CPU backend runs, in `src/systems/relief/isostasy.rs`).
//!
//! What crosses the bus: the smoothed root w (the regional response, computed on the host by
//! the coarse or fine smoothing passes, 4 bytes a sample) and the trench depth (4 bytes a
//! sample; the fronts read it on the host too) go up every call; the age–depth table (8,002
//! f32) goes up when it changes (once per run). Crust type, thickness and age are the resident
//! crust buffers. Nothing is read back: the elevation stays on the device, marked newer
//! ([`WRITES`]).

use crate::gpu::{
    FieldMask, GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/isostasy.wgsl");

const KERNEL: &str = "isostasy";

/// The field the kernel writes on the device.
pub const WRITES: FieldMask = FieldMask::ELEVATION;

/// The constants of the isostatic combine (f64; the CPU reference computes with them as they
/// are, the kernel rounds them to f32).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IsostasyConstants {
    /// Reference continental thickness T₀, km.
    pub ref_thickness_km: f64,
    /// Surface elevation of the reference column h₀, km.
    pub ref_elevation_km: f64,
    /// Root per km of extra crust, ρ_c/ρ_m.
    pub root_ratio: f64,
    /// Mantle density ρ_m, g/cm³.
    pub rho_mantle: f64,
    /// Sea-water density ρ_w, g/cm³.
    pub rho_water: f64,
    /// Most the plate holds a sample away from its own root, S, km (may be infinite).
    pub max_support_km: f64,
    /// Oceanic crust thickness T_oc, km: what lies above it is load (sediment, arcs).
    pub oceanic_thickness_km: f64,
    /// Sea-floor rise per km of load, (ρ_m − ρ_s)/(ρ_m − ρ_w).
    pub sediment_gain: f64,
    /// Most load (km of crust above `oceanic_thickness_km`) that raises the sea floor: a
    /// thicker column is held at that level (may be infinite).
    pub max_oceanic_load_km: f64,
    /// Most continental crust (km) that floats: a thicker column stands where one this thick
    /// would (its excess root is lost to the mantle; may be infinite).
    pub max_continental_km: f64,
}

/// The age–depth law sampled every `step_my` from age 0 (what
/// [`AgeDepthTable`](crate::systems::relief::isostasy::AgeDepthTable) interpolates).
#[derive(Clone, Copy, Debug)]
pub struct AgeDepthSamples<'a> {
    /// Ocean depth (km, positive down) at ages 0, step, 2·step, …; at least two entries.
    pub depth_km: &'a [f64],
    /// Age step, My.
    pub step_my: f64,
    /// Ages are clamped to this, My.
    pub max_age_my: f64,
}

/// Uniforms of one call. Keep in sync with `IsostasyUniforms` in shaders/isostasy.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct IsostasyUniforms {
    /// T₀, km.
    pub ref_thickness_km: f32,
    /// h₀, km.
    pub ref_elevation_km: f32,
    /// ρ_c/ρ_m.
    pub root_ratio: f32,
    /// ρ_m/(ρ_m − ρ_w): a dry elevation below sea level is multiplied by this.
    pub submerge_factor: f32,
    /// S, km (an infinite S becomes 1e30).
    pub max_support_km: f32,
    /// T_oc, km.
    pub oceanic_thickness_km: f32,
    /// (ρ_m − ρ_s)/(ρ_m − ρ_w).
    pub sediment_gain: f32,
    /// 1/step of the age–depth table, 1/My.
    pub age_scale: f32,
    /// Oldest age of the table, My.
    pub max_age_my: f32,
    /// Entries of the table minus 2 (the last interval's first entry).
    pub table_last: u32,
    /// Samples.
    pub count: u32,
    /// Threads per dispatch row.
    pub row_stride: u32,
    /// Most load that raises the sea floor, km (infinite becomes 1e30).
    pub max_oceanic_load_km: f32,
    /// Most continental crust that floats, km (infinite becomes 1e30).
    pub max_continental_km: f32,
    /// Padding to 16 bytes.
    pub _pad: [u32; 2],
}

impl IsostasyUniforms {
    /// The uniforms for `c` and a table of `table_len` entries over `count` samples.
    pub fn new(c: &IsostasyConstants, table: &AgeDepthSamples, count: u32) -> Self {
        Self {
            ref_thickness_km: c.ref_thickness_km as f32,
            ref_elevation_km: c.ref_elevation_km as f32,
            root_ratio: c.root_ratio as f32,
            submerge_factor: (c.rho_mantle / (c.rho_mantle - c.rho_water)) as f32,
            max_support_km: c.max_support_km.min(1e30) as f32,
            oceanic_thickness_km: c.oceanic_thickness_km as f32,
            sediment_gain: c.sediment_gain as f32,
            age_scale: (1.0 / table.step_my) as f32,
            max_age_my: table.max_age_my as f32,
            table_last: table.depth_km.len().saturating_sub(2) as u32,
            count,
            row_stride: ROW_STRIDE,
            max_oceanic_load_km: c.max_oceanic_load_km.min(1e30) as f32,
            max_continental_km: c.max_continental_km.min(1e30) as f32,
            _pad: [0; 2],
        }
    }
}

/// Pipeline and buffers of the kernel.
pub(crate) struct IsostasyKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    /// The smoothed root and the trench depth, and their length in samples.
    inputs: Option<(wgpu::Buffer, wgpu::Buffer, usize)>,
    /// The age–depth table on the device and the f32 values it holds.
    table: Option<(wgpu::Buffer, Vec<f32>)>,
    bind_group: Option<wgpu::BindGroup>,
}

impl Kernel for IsostasyKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, KERNEL, WGSL),
            uniforms: uniform_buffer(
                device,
                "isostasy uniforms",
                std::mem::size_of::<IsostasyUniforms>(),
            ),
            inputs: None,
            table: None,
            bind_group: None,
        }
    }
    fn forget_bind_groups(&mut self) {
        self.bind_group = None;
    }
}

fn fail(message: String) -> GpuError {
    GpuError::Kernel {
        kernel: KERNEL,
        message,
    }
}

/// The isostatic elevation of every sample, written into the resident elevation buffer (call
/// [`GpuContext::sync_crust`] first; crust type, thickness and age are read from the resident
/// buffers). `deflection_km` is the smoothed root w and `trench_km` the trench depth, one per
/// sample. The caller marks [`WRITES`] newer ([`GpuContext::note_device_write`]).
pub fn isostasy_dispatch(
    ctx: &mut GpuContext,
    c: &IsostasyConstants,
    table: &AgeDepthSamples,
    deflection_km: &[f32],
    trench_km: &[f32],
) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, k: &mut IsostasyKernel| {
        let Some(n) = ctx.crust_buffers().map(|b| b.len) else {
            return Err(fail("the crust is not on the device".into()));
        };
        if deflection_km.len() != n || trench_km.len() != n {
            return Err(fail(format!(
                "{} deflections and {} trench depths for a crust of {n} samples",
                deflection_km.len(),
                trench_km.len()
            )));
        }
        if table.depth_km.len() < 2 || table.step_my.is_nan() || table.step_my <= 0.0 {
            return Err(fail(format!(
                "an age–depth table of {} entries every {} My",
                table.depth_km.len(),
                table.step_my
            )));
        }
        if n == 0 {
            return Ok(());
        }
        if k.inputs.as_ref().is_none_or(|i| i.2 != n) {
            k.inputs = Some((
                ctx.storage_buffer("isostasy deflection", 4 * n),
                ctx.storage_buffer("isostasy trench", 4 * n),
                n,
            ));
            k.bind_group = None;
        }
        let values: Vec<f32> = table.depth_km.iter().map(|&d| d as f32).collect();
        if k.table.as_ref().is_none_or(|(_, v)| *v != values) {
            let buf = ctx.storage_buffer("isostasy age-depth table", 4 * values.len());
            ctx.upload(&buf, bytemuck::cast_slice(&values));
            k.table = Some((buf, values));
            k.bind_group = None;
        }
        if k.bind_group.is_none() {
            let (Some(b), Some((defl, trench, _)), Some((tb, _))) =
                (ctx.crust_buffers(), k.inputs.as_ref(), k.table.as_ref())
            else {
                return Err(fail("buffers missing".into()));
            };
            let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("isostasy bindings"),
                layout: &k.pipeline.get_bind_group_layout(0),
                entries: &[
                    entry(0, &k.uniforms),
                    entry(1, &b.elevation_km),
                    entry(2, &b.crust_type),
                    entry(3, &b.thickness_km),
                    entry(4, &b.age_my),
                    entry(5, defl),
                    entry(6, trench),
                    entry(7, tb),
                ],
            });
            k.bind_group = Some(bg);
        }
        let (Some(bg), Some((defl, trench, _))) = (k.bind_group.clone(), k.inputs.clone()) else {
            return Err(fail("buffers missing".into()));
        };
        let u = IsostasyUniforms::new(c, table, n as u32);
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        ctx.upload(&defl, bytemuck::cast_slice(deflection_km));
        ctx.upload(&trench, bytemuck::cast_slice(trench_km));
        ctx.dispatch(KERNEL, &pipeline, &bg, n as u32)?;
        ctx.traffic.isostasy_passes += 1;
        Ok(())
    })
}
