//! The 3D globe, drawn by wgpu through an egui paint callback with `shaders/globe.wgsl`: a grid
//! sphere displaced by the elevation (exaggerated), coloured by the current overlay, with an
//! optional sea surface; orbit by dragging, zoom with the wheel.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use eframe::egui;
use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait, RenderState, ScreenDescriptor};
use eframe::wgpu;
use glam::{Mat4, Vec3};

/// The WGSL source of the globe.
pub const GLOBE_WGSL: &str = include_str!("../../shaders/globe.wgsl");

/// Grid resolution: longitude segments (latitude segments are half).
const LON_SEGMENTS: u32 = 256;

/// Uniforms; keep in sync with `Globe` in shaders/globe.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GlobeUniforms {
    /// Clip from world.
    pub view_proj: [[f32; 4]; 4],
    /// Toward the sun (xyz), world frame.
    pub light_dir: [f32; 4],
    /// x: radius change per km; y: sea surface (1/0).
    pub params: [f32; 4],
}

/// Where the camera is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Longitude of the eye, radians.
    pub yaw: f32,
    /// Latitude of the eye, radians.
    pub pitch: f32,
    /// Distance of the eye from the centre, planet radii.
    pub distance: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            yaw: 0.3,
            pitch: 0.35,
            distance: 3.2,
        }
    }
}

impl Camera {
    /// The eye position.
    pub fn eye(&self) -> Vec3 {
        Vec3::new(
            self.pitch.cos() * self.yaw.cos(),
            self.pitch.cos() * self.yaw.sin(),
            self.pitch.sin(),
        ) * self.distance
    }
    /// Clip from world for a viewport of this aspect ratio.
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        let view = glam::camera::rh::view::look_at_mat4(self.eye(), Vec3::ZERO, Vec3::Z);
        // wgpu's clip space: z in [0, 1], y up.
        let proj = glam::camera::rh::proj::directx::perspective(0.7, aspect.max(0.1), 0.05, 20.0);
        proj * view
    }
    /// The point of the unit sphere under normalised device coordinates (x, y in [-1, 1]), if
    /// the ray hits the sphere.
    pub fn pick(&self, aspect: f32, ndc: [f32; 2]) -> Option<Vec3> {
        let inv = self.view_proj(aspect).inverse();
        let near = inv.project_point3(Vec3::new(ndc[0], ndc[1], 0.0));
        let far = inv.project_point3(Vec3::new(ndc[0], ndc[1], 1.0));
        let d = (far - near).normalize_or_zero();
        let b = near.dot(d);
        let c = near.length_squared() - 1.0;
        let disc = b * b - c;
        if disc < 0.0 {
            return None;
        }
        let t = -b - disc.sqrt();
        (t > 0.0).then(|| (near + d * t).normalize())
    }
}

/// GPU objects of the globe (kept in egui-wgpu's callback resources).
struct GlobeResources {
    pipeline: wgpu::RenderPipeline,
    map_pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    uniforms: wgpu::Buffer,
    sampler: wgpu::Sampler,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    bind_group: Option<wgpu::BindGroup>,
    textures: Option<(wgpu::Texture, wgpu::Texture)>,
    uploaded: u64,
}

/// Creates the globe's pipeline and buffers; call once with the app's render state.
pub fn init(rs: &RenderState) {
    let device = &rs.device;
    let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("globe.wgsl"),
        source: wgpu::ShaderSource::Wgsl(GLOBE_WGSL.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("globe"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 2,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
        ],
    });
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("globe"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("globe"),
        layout: Some(&pl),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: 8,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &wgpu::vertex_attr_array![0 => Float32x2],
            })],
        },
        fragment: Some(wgpu::FragmentState {
            module: &shader,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(rs.target_format.into())],
        }),
        primitive: wgpu::PrimitiveState {
            cull_mode: Some(wgpu::Face::Back),
            ..Default::default()
        },
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        multiview_mask: None,
        cache: None,
    });
    // The flat map: one quad over the callback's rectangle, the colours read texel by texel
    // (no filtering, no blending: the cheapest fragments a software rasteriser can draw).
    let map_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("map"),
        layout: Some(&pl),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_map"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        fragment: Some(wgpu::FragmentState {
            module: &shader,
            entry_point: Some("fs_map"),
            compilation_options: Default::default(),
            targets: &[Some(rs.target_format.into())],
        }),
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        multiview_mask: None,
        cache: None,
    });
    let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("globe uniforms"),
        size: std::mem::size_of::<GlobeUniforms>() as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("globe"),
        address_mode_u: wgpu::AddressMode::Repeat,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    let (verts, idx) = grid_sphere(LON_SEGMENTS);
    use wgpu::util::DeviceExt;
    let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("globe vertices"),
        contents: bytemuck::cast_slice(&verts),
        usage: wgpu::BufferUsages::VERTEX,
    });
    let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("globe indices"),
        contents: bytemuck::cast_slice(&idx),
        usage: wgpu::BufferUsages::INDEX,
    });
    rs.renderer
        .write()
        .callback_resources
        .insert(GlobeResources {
            pipeline,
            map_pipeline,
            layout,
            uniforms,
            sampler,
            vertices,
            indices,
            index_count: idx.len() as u32,
            bind_group: None,
            textures: None,
            uploaded: 0,
        });
}

/// A latitude/longitude grid: (lat, lon) in radians per vertex, triangles counter-clockwise
/// seen from outside.
pub fn grid_sphere(lon_segments: u32) -> (Vec<[f32; 2]>, Vec<u32>) {
    let lat_segments = lon_segments / 2;
    let mut v = Vec::new();
    for j in 0..=lat_segments {
        let lat =
            -std::f32::consts::FRAC_PI_2 + std::f32::consts::PI * j as f32 / lat_segments as f32;
        for i in 0..=lon_segments {
            let lon =
                -std::f32::consts::PI + 2.0 * std::f32::consts::PI * i as f32 / lon_segments as f32;
            v.push([lat, lon]);
        }
    }
    let row = lon_segments + 1;
    let mut idx = Vec::new();
    for j in 0..lat_segments {
        for i in 0..lon_segments {
            let a = j * row + i;
            let b = a + 1;
            let c = b + row;
            let d = a + row;
            idx.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    (v, idx)
}

/// What the globe's textures hold: the overlay colours (RGBA8, sRGB) and the elevation (km)
/// of the equirectangular grid. Made off the UI thread when a new snapshot or overlay
/// arrives, and uploaded once per change (two texture writes).
#[derive(Debug, Default)]
pub struct GlobeData {
    /// Width and height of the grid, pixels.
    pub size: [usize; 2],
    /// Overlay colour per pixel, RGBA8 (sRGB, unmultiplied), rows north to south.
    pub rgba: Vec<u8>,
    /// Elevation per pixel, km.
    pub elevation_km: Vec<f32>,
}

impl GlobeData {
    /// The data of a coloured map and its elevation grid.
    pub fn new(colours: &egui::ColorImage, elevation_km: Vec<f32>) -> Self {
        let mut rgba = Vec::with_capacity(colours.pixels.len() * 4);
        for p in &colours.pixels {
            rgba.extend_from_slice(&p.to_srgba_unmultiplied());
        }
        Self {
            size: colours.size,
            rgba,
            elevation_km,
        }
    }
}

/// One frame's globe: the camera, the look, and (when new) the textures to upload.
pub struct GlobeCallback {
    /// Uniforms for this frame (the aspect ratio comes from the rect).
    pub uniforms: GlobeUniforms,
    /// Identifies the texture contents; uploaded when it changes.
    pub generation: u64,
    /// The texture contents.
    pub data: Arc<GlobeData>,
}

impl CallbackTrait for GlobeCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        _screen: &ScreenDescriptor,
        _encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(r) = resources.get_mut::<GlobeResources>() else {
            return Vec::new();
        };
        queue.write_buffer(&r.uniforms, 0, bytemuck::bytes_of(&self.uniforms));
        upload(r, device, queue, self.generation, &self.data);
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        let Some(r) = resources.get::<GlobeResources>() else {
            return;
        };
        let Some(bg) = &r.bind_group else { return };
        pass.set_pipeline(&r.pipeline);
        pass.set_bind_group(0, bg, &[]);
        pass.set_vertex_buffer(0, r.vertices.slice(..));
        pass.set_index_buffer(r.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..r.index_count, 0, 0..1);
    }
}

/// Uploads `data` into the textures (made or remade at its size) unless `generation` is
/// there already: one write per texture per new picture, nothing on other frames.
fn upload(
    r: &mut GlobeResources,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    generation: u64,
    data: &GlobeData,
) {
    if r.uploaded != generation || r.bind_group.is_none() {
        let [w, h] = data.size;
        if w == 0 || h == 0 || data.rgba.len() != w * h * 4 {
            return;
        }
        let size = wgpu::Extent3d {
            width: w as u32,
            height: h as u32,
            depth_or_array_layers: 1,
        };
        let make = |format, label| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        };
        let same_size = r
            .textures
            .as_ref()
            .is_some_and(|(c, _)| c.width() == w as u32 && c.height() == h as u32);
        if !same_size {
            r.textures = Some((
                make(wgpu::TextureFormat::Rgba8Unorm, "globe colours"),
                make(wgpu::TextureFormat::R32Float, "globe elevation"),
            ));
            r.bind_group = None;
        }
        if let Some((ct, et)) = &r.textures {
            let write = |t: &wgpu::Texture, data: &[u8], bpp: u32| {
                queue.write_texture(
                    t.as_image_copy(),
                    data,
                    wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(w as u32 * bpp),
                        rows_per_image: Some(h as u32),
                    },
                    size,
                );
            };
            write(ct, &data.rgba, 4);
            if data.elevation_km.len() == w * h {
                write(et, bytemuck::cast_slice(&data.elevation_km), 4);
            }
            if r.bind_group.is_none() {
                let cv = ct.create_view(&Default::default());
                let ev = et.create_view(&Default::default());
                r.bind_group = Some(device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("globe"),
                    layout: &r.layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: r.uniforms.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::TextureView(&cv),
                        },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: wgpu::BindingResource::Sampler(&r.sampler),
                        },
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: wgpu::BindingResource::TextureView(&ev),
                        },
                    ],
                }));
            }
        }
        r.uploaded = generation;
    }
}

/// One frame's flat map (the 2D view), drawn from the same textures as the globe.
pub struct MapCallback {
    /// Identifies the texture contents; uploaded when it changes.
    pub generation: u64,
    /// The texture contents.
    pub data: Arc<GlobeData>,
}

impl CallbackTrait for MapCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        _screen: &ScreenDescriptor,
        _encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        if let Some(r) = resources.get_mut::<GlobeResources>() {
            upload(r, device, queue, self.generation, &self.data);
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        let Some(r) = resources.get::<GlobeResources>() else {
            return;
        };
        let Some(bg) = &r.bind_group else { return };
        pass.set_pipeline(&r.map_pipeline);
        pass.set_bind_group(0, bg, &[]);
        pass.draw(0..6, 0..1);
    }
}

/// The paint callback of the flat map for `rect`.
pub fn map_callback(rect: egui::Rect, cb: MapCallback) -> egui::PaintCallback {
    egui_wgpu::Callback::new_paint_callback(rect, cb)
}

/// The paint callback for `rect`.
pub fn paint_callback(rect: egui::Rect, cb: GlobeCallback) -> egui::PaintCallback {
    egui_wgpu::Callback::new_paint_callback(rect, cb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globe_wgsl_validates_with_naga() {
        let module = naga::front::wgsl::parse_str(GLOBE_WGSL).expect("globe.wgsl parses");
        let info = naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&module)
        .expect("globe.wgsl validates");
        let _ = info;
        let names: Vec<&str> = module
            .entry_points
            .iter()
            .map(|e| e.name.as_str())
            .collect();
        assert!(
            ["vs_main", "fs_main", "vs_map", "fs_map"]
                .iter()
                .all(|n| names.contains(n)),
            "{names:?}"
        );
        // The uniform block matches the host struct's size.
        let globe = module
            .global_variables
            .iter()
            .find(|(_, g)| g.name.as_deref() == Some("globe"))
            .expect("the `globe` uniform");
        let size = module.types[globe.1.ty].inner.size(module.to_ctx());
        assert_eq!(size as usize, std::mem::size_of::<GlobeUniforms>());
    }

    #[test]
    fn grid_triangles_face_outward() {
        let (v, idx) = grid_sphere(16);
        let p = |i: u32| {
            let [lat, lon] = v[i as usize];
            Vec3::new(lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin())
        };
        let mut outward = 0;
        let mut total = 0;
        for t in idx.chunks(3) {
            let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
            let n = (b - a).cross(c - a);
            if n.length() < 1e-6 {
                continue; // degenerate at the poles
            }
            total += 1;
            if n.dot(a + b + c) > 0.0 {
                outward += 1;
            }
        }
        assert_eq!(outward, total);
    }

    #[test]
    fn picking_the_centre_of_the_view_hits_the_point_under_the_eye() {
        let cam = Camera::default();
        let hit = cam
            .pick(1.6, [0.0, 0.0])
            .expect("the centre ray hits the globe");
        assert!(hit.dot(cam.eye().normalize()) > 0.9999);
        assert!(
            cam.pick(1.6, [1.0, 1.0]).is_none(),
            "the corner looks past the globe"
        );
    }
}
