//! The 3D view on the GPU: an egui wgpu paint callback. Pipelines, the uniform buffer and the vertex buffers are built
//! once ([`GpuResources::install`], stored in egui-wgpu's `callback_resources`); vertex data are uploaded only when the
//! scene geometry changes ([`GpuResources::upload`]), so a frame's callback carries only the camera matrix (plus the
//! draw toggles).

use std::borrow::Cow;

use eframe::egui_wgpu::{self, wgpu, CallbackResources, CallbackTrait, RenderState};
use glam::{Mat4, Vec3};

use super::geometry::{SceneGeometry, Vertex, VERTEX_FLOATS};
use super::DrawFlags;
use crate::state::MembraneStyle;

/// Depth buffer bits requested from eframe (`NativeOptions::depth_buffer`); the pipelines use the matching format.
pub const DEPTH_BITS: u8 = 32;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// view_proj (16 floats) + light direction (4 floats).
const UNIFORM_FLOATS: usize = 20;

/// One vertex buffer and how many vertices it holds.
struct Buffer {
    buffer: wgpu::Buffer,
    capacity: u64,
    count: u32,
}

/// GPU resources of the 3D view, created once per wgpu device.
pub struct GpuResources {
    opaque: wgpu::RenderPipeline,
    translucent: wgpu::RenderPipeline,
    lines: wgpu::RenderPipeline,
    uniform: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// object, contacts, membrane, membrane lines, frustum lines, grid lines.
    buffers: [Option<Buffer>; 6],
    /// Geometry version currently on the GPU.
    pub version: Option<u64>,
}

impl GpuResources {
    /// Build pipelines and buffers and store them in the renderer's callback resources (once, at start-up).
    pub fn install(rs: &RenderState) {
        let res = Self::new(&rs.device, rs.target_format);
        rs.renderer.write().callback_resources.insert(res);
    }

    fn new(device: &wgpu::Device, target: wgpu::TextureFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("tnd_view3d"),
            source: wgpu::ShaderSource::Wgsl(Cow::Borrowed(include_str!("shader.wgsl"))),
        });
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tnd_view3d_uniform"),
            size: (UNIFORM_FLOATS * 4) as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("tnd_view3d_bgl"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("tnd_view3d_bg"),
            layout: &layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("tnd_view3d_layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |topology, blend: Option<wgpu::BlendState>, depth_write: bool| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("tnd_view3d_pipeline"),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: (VERTEX_FLOATS * 4) as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x4],
                    })],
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(depth_write),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: wgpu::StencilState::default(),
                    bias: wgpu::DepthBiasState::default(),
                }),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: target,
                        blend,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let premultiplied = Some(wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING);
        Self {
            opaque: pipeline(wgpu::PrimitiveTopology::TriangleList, None, true),
            translucent: pipeline(wgpu::PrimitiveTopology::TriangleList, premultiplied, false),
            lines: pipeline(wgpu::PrimitiveTopology::LineList, premultiplied, true),
            uniform,
            bind_group,
            buffers: Default::default(),
            version: None,
        }
    }

    /// Upload `geom` if it is not on the GPU yet (buffers grow when needed, and are otherwise rewritten in place).
    pub fn upload(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, geom: &SceneGeometry) {
        if self.version == Some(geom.version) {
            return;
        }
        let parts: [&[Vertex]; 6] = [
            &geom.object,
            &geom.contacts,
            &geom.membrane,
            &geom.membrane_lines,
            &geom.frustum_lines,
            &geom.grid_lines,
        ];
        for (slot, verts) in self.buffers.iter_mut().zip(parts) {
            let bytes = SceneGeometry::vertex_bytes(verts);
            let size = bytes.len() as u64;
            if size == 0 {
                if let Some(b) = slot {
                    b.count = 0;
                }
                continue;
            }
            if slot.as_ref().is_none_or(|b| b.capacity < size) {
                let capacity = size.next_power_of_two();
                *slot = Some(Buffer {
                    buffer: device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("tnd_view3d_vertices"),
                        size: capacity,
                        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                        mapped_at_creation: false,
                    }),
                    capacity,
                    count: 0,
                });
            }
            if let Some(b) = slot {
                queue.write_buffer(&b.buffer, 0, &bytes);
                b.count = verts.len() as u32;
            }
        }
        self.version = Some(geom.version);
    }
}

/// Upload `geom` into the installed resources, if any.
pub fn upload(rs: &RenderState, geom: &SceneGeometry) {
    let mut renderer = rs.renderer.write();
    if let Some(res) = renderer.callback_resources.get_mut::<GpuResources>() {
        res.upload(&rs.device, &rs.queue, geom);
    }
}

/// One frame's paint callback: the camera and the draw toggles.
pub struct ViewCallback {
    pub view_proj: Mat4,
    pub light: Vec3,
    pub flags: DrawFlags,
}

impl ViewCallback {
    /// The callback as an egui shape covering `rect`.
    pub fn shape(self, rect: egui::Rect) -> egui::Shape {
        egui::Shape::Callback(egui_wgpu::Callback::new_paint_callback(rect, self))
    }
}

impl CallbackTrait for ViewCallback {
    fn prepare(
        &self,
        _device: &wgpu::Device,
        queue: &wgpu::Queue,
        _screen: &egui_wgpu::ScreenDescriptor,
        _encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        if let Some(res) = resources.get::<GpuResources>() {
            let mut bytes = Vec::with_capacity(UNIFORM_FLOATS * 4);
            for x in self
                .view_proj
                .to_cols_array()
                .iter()
                .chain(&self.light.extend(0.0).to_array())
            {
                bytes.extend_from_slice(&x.to_ne_bytes());
            }
            queue.write_buffer(&res.uniform, 0, &bytes);
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        let Some(res) = resources.get::<GpuResources>() else {
            return;
        };
        pass.set_bind_group(0, &res.bind_group, &[]);
        let draw =
            |pass: &mut wgpu::RenderPass<'static>, pipeline: &wgpu::RenderPipeline, i: usize| {
                if let Some(b) = &res.buffers[i] {
                    if b.count > 0 {
                        pass.set_pipeline(pipeline);
                        pass.set_vertex_buffer(0, b.buffer.slice(..));
                        pass.draw(0..b.count, 0..1);
                    }
                }
            };
        draw(pass, &res.lines, 5);
        draw(pass, &res.opaque, 0);
        if self.flags.contacts {
            draw(pass, &res.opaque, 1);
        }
        if self.flags.frustum {
            draw(pass, &res.lines, 4);
        }
        match self.flags.membrane {
            MembraneStyle::Translucent => draw(pass, &res.translucent, 2),
            MembraneStyle::Wireframe => draw(pass, &res.lines, 3),
            MembraneStyle::Hidden => {}
        }
    }
}
