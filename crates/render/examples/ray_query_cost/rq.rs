//! A Vulkan device opened with VK_KHR_acceleration_structure and VK_KHR_ray_query, the
//! driver's own BVH built from a scene's meshes, and the closest-hit kernel (kernel.wgsl) run
//! through it. Only what the measurement needs: one queue, host-visible ray and hit buffers.

use std::error::Error;
use std::ffi::CStr;

use ash::{khr, vk};
use lightfarm_render::scene::Scene;

type Res<T> = Result<T, Box<dyn Error>>;

pub struct Buffer {
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    ptr: *mut u8,
    size: u64,
    pub addr: u64,
}

pub struct RqDevice {
    _entry: ash::Entry,
    instance: ash::Instance,
    device: ash::Device,
    asx: khr::acceleration_structure::Device,
    queue: vk::Queue,
    pool: vk::CommandPool,
    memory: vk::PhysicalDeviceMemoryProperties,
    scratch_align: u64,
    pub name: String,
    buffers: Vec<Buffer>,
    structures: Vec<vk::AccelerationStructureKHR>,
}

fn has_ext(exts: &[vk::ExtensionProperties], name: &CStr) -> bool {
    exts.iter()
        .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
}

impl RqDevice {
    /// The first device (GPUs before the CPU) that offers hardware-style ray queries.
    pub fn new() -> Res<RqDevice> {
        // SAFETY: every call below is on handles created here; pNext chains borrow locals that
        // outlive the calls.
        unsafe {
            let entry = ash::Entry::load()?;
            let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_3);
            let instance = entry.create_instance(
                &vk::InstanceCreateInfo::default().application_info(&app),
                None,
            )?;
            let wanted = [
                khr::acceleration_structure::NAME,
                khr::ray_query::NAME,
                khr::deferred_host_operations::NAME,
            ];
            let mut chosen = None;
            let mut devices = instance.enumerate_physical_devices()?;
            devices.sort_by_key(|&d| {
                let t = instance.get_physical_device_properties(d).device_type;
                (t == vk::PhysicalDeviceType::CPU) as u8
            });
            for pd in devices {
                let exts = instance.enumerate_device_extension_properties(pd)?;
                if wanted.iter().all(|w| has_ext(&exts, w)) {
                    chosen = Some(pd);
                    break;
                }
            }
            let pd = chosen.ok_or("no Vulkan device offers VK_KHR_ray_query and VK_KHR_acceleration_structure (lavapipe has them from Mesa 24.1: source scripts/lavapipe-backports.sh)")?;
            let props = instance.get_physical_device_properties(pd);
            let name = props
                .device_name_as_c_str()
                .map(|c| c.to_string_lossy().into_owned())
                .unwrap_or_default();
            let mut asp = vk::PhysicalDeviceAccelerationStructurePropertiesKHR::default();
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut asp);
            instance.get_physical_device_properties2(pd, &mut p2);
            let scratch_align = u64::from(
                asp.min_acceleration_structure_scratch_offset_alignment
                    .max(1),
            );
            let family = instance
                .get_physical_device_queue_family_properties(pd)
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
                .ok_or("no compute queue")? as u32;
            let mut f12 = vk::PhysicalDeviceVulkan12Features::default().buffer_device_address(true);
            let mut fas = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default()
                .acceleration_structure(true);
            let mut frq = vk::PhysicalDeviceRayQueryFeaturesKHR::default().ray_query(true);
            let prio = [1.0f32];
            let queues = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(family)
                .queue_priorities(&prio)];
            let names: Vec<*const i8> = wanted.iter().map(|n| n.as_ptr()).collect();
            let create = vk::DeviceCreateInfo::default()
                .queue_create_infos(&queues)
                .enabled_extension_names(&names)
                .push_next(&mut f12)
                .push_next(&mut fas)
                .push_next(&mut frq);
            let device = instance.create_device(pd, &create, None)?;
            let queue = device.get_device_queue(family, 0);
            let pool = device.create_command_pool(
                &vk::CommandPoolCreateInfo::default().queue_family_index(family),
                None,
            )?;
            let asx = khr::acceleration_structure::Device::new(&instance, &device);
            let memory = instance.get_physical_device_memory_properties(pd);
            Ok(RqDevice {
                _entry: entry,
                instance,
                device,
                asx,
                queue,
                pool,
                memory,
                scratch_align,
                name,
                buffers: Vec::new(),
                structures: Vec::new(),
            })
        }
    }

    /// A buffer with a device address; `host` ones are mapped (every type is on lavapipe).
    fn buffer(&mut self, size: u64, usage: vk::BufferUsageFlags, host: bool) -> Res<usize> {
        // SAFETY: handles of this device; the memory is bound before use and freed in Drop.
        unsafe {
            let info = vk::BufferCreateInfo::default()
                .size(size.max(16))
                .usage(usage | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS);
            let buffer = self.device.create_buffer(&info, None)?;
            let req = self.device.get_buffer_memory_requirements(buffer);
            let mapped =
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
            let local = vk::MemoryPropertyFlags::DEVICE_LOCAL;
            // Mapped buffers in device memory where the GPU offers it (resizable BAR), so the
            // kernel does not read its rays across the bus; every type is both on lavapipe.
            let preferences = if host {
                vec![mapped | local, mapped]
            } else {
                vec![local]
            };
            let ty = preferences
                .iter()
                .find_map(|&want| {
                    (0..self.memory.memory_type_count).find(|&i| {
                        req.memory_type_bits & (1 << i) != 0
                            && self.memory.memory_types[i as usize]
                                .property_flags
                                .contains(want)
                    })
                })
                .ok_or("no memory type for a ray-query buffer")?;
            let mut flags = vk::MemoryAllocateFlagsInfo::default()
                .flags(vk::MemoryAllocateFlags::DEVICE_ADDRESS);
            let alloc = vk::MemoryAllocateInfo::default()
                .allocation_size(req.size)
                .memory_type_index(ty)
                .push_next(&mut flags);
            let memory = self.device.allocate_memory(&alloc, None)?;
            self.device.bind_buffer_memory(buffer, memory, 0)?;
            let ptr = if host {
                self.device
                    .map_memory(memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())?
                    as *mut u8
            } else {
                std::ptr::null_mut()
            };
            let addr = self
                .device
                .get_buffer_device_address(&vk::BufferDeviceAddressInfo::default().buffer(buffer));
            self.buffers.push(Buffer {
                buffer,
                memory,
                ptr,
                size,
                addr,
            });
            Ok(self.buffers.len() - 1)
        }
    }

    fn upload(&mut self, bytes: &[u8], usage: vk::BufferUsageFlags) -> Res<usize> {
        let b = self.buffer(bytes.len() as u64, usage, true)?;
        self.write(b, bytes)?;
        Ok(b)
    }

    pub fn write(&self, b: usize, bytes: &[u8]) -> Res<()> {
        let buf = &self.buffers[b];
        if buf.ptr.is_null() || bytes.len() as u64 > buf.size {
            return Err("write past a buffer's end or into an unmapped buffer".into());
        }
        // SAFETY: the mapping covers `size` bytes, checked above; host-coherent memory.
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf.ptr, bytes.len()) };
        Ok(())
    }

    pub fn read_vec4(&self, b: usize, n: usize) -> Res<Vec<[f32; 4]>> {
        let buf = &self.buffers[b];
        if buf.ptr.is_null() || (n as u64) * 16 > buf.size {
            return Err("read past a buffer's end".into());
        }
        let mut out = vec![[0f32; 4]; n];
        // SAFETY: as in `write`; the device finished writing (fence) before this is called.
        unsafe {
            std::ptr::copy_nonoverlapping(buf.ptr, out.as_mut_ptr() as *mut u8, n * 16);
        }
        Ok(out)
    }

    pub fn submit(&self, record: impl FnOnce(&ash::Device, vk::CommandBuffer)) -> Res<()> {
        // SAFETY: a fresh command buffer of this device's pool, waited on before it is freed.
        unsafe {
            let cmd = self.device.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(self.pool)
                    .command_buffer_count(1),
            )?[0];
            self.device
                .begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())?;
            record(&self.device, cmd);
            let all = vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                .dst_access_mask(vk::AccessFlags::HOST_READ | vk::AccessFlags::MEMORY_READ);
            self.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::HOST | vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[all],
                &[],
                &[],
            );
            self.device.end_command_buffer(cmd)?;
            let fence = self
                .device
                .create_fence(&vk::FenceCreateInfo::default(), None)?;
            let cmds = [cmd];
            self.device.queue_submit(
                self.queue,
                &[vk::SubmitInfo::default().command_buffers(&cmds)],
                fence,
            )?;
            self.device.wait_for_fences(&[fence], true, u64::MAX)?;
            self.device.destroy_fence(fence, None);
            self.device.free_command_buffers(self.pool, &cmds);
        }
        Ok(())
    }

    /// Builds one structure from `geom` (one geometry of `prims` primitives) on the device.
    fn build(
        &mut self,
        ty: vk::AccelerationStructureTypeKHR,
        geom: vk::AccelerationStructureGeometryKHR<'_>,
        prims: u32,
    ) -> Res<(vk::AccelerationStructureKHR, u64)> {
        let geoms = [geom];
        let mut info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(ty)
            .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&geoms);
        let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
        // SAFETY: the geometry's addresses are live buffers of this device.
        unsafe {
            self.asx.get_acceleration_structure_build_sizes(
                vk::AccelerationStructureBuildTypeKHR::DEVICE,
                &info,
                &[prims],
                &mut sizes,
            );
        }
        let storage = self.buffer(
            sizes.acceleration_structure_size,
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR,
            false,
        )?;
        let scratch = self.buffer(
            sizes.build_scratch_size + self.scratch_align,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            false,
        )?;
        let scratch_addr = self.buffers[scratch]
            .addr
            .next_multiple_of(self.scratch_align);
        // SAFETY: as above; the build is waited on before the scratch could be reused.
        unsafe {
            let handle = self.asx.create_acceleration_structure(
                &vk::AccelerationStructureCreateInfoKHR::default()
                    .buffer(self.buffers[storage].buffer)
                    .size(sizes.acceleration_structure_size)
                    .ty(ty),
                None,
            )?;
            self.structures.push(handle);
            info =
                info.dst_acceleration_structure(handle)
                    .scratch_data(vk::DeviceOrHostAddressKHR {
                        device_address: scratch_addr,
                    });
            let range =
                [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(prims)];
            let asx = &self.asx;
            self.submit(|_, cmd| asx.cmd_build_acceleration_structures(cmd, &[info], &[&range]))?;
            let addr = self.asx.get_acceleration_structure_device_address(
                &vk::AccelerationStructureDeviceAddressInfoKHR::default()
                    .acceleration_structure(handle),
            );
            Ok((handle, addr))
        }
    }

    /// One BLAS per mesh, a TLAS with the scene's instances in their order (so a hit's
    /// instance index is the scene's instance index and its primitive the mesh's triangle).
    pub fn build_scene(&mut self, scene: &Scene) -> Res<vk::AccelerationStructureKHR> {
        let input = vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR;
        let mut blas_addr = vec![None; scene.meshes.len()];
        for (mi, mesh) in scene.meshes.iter().enumerate() {
            let prims = (mesh.indices.len() / 3) as u32;
            if prims == 0 || mesh.positions.is_empty() {
                continue;
            }
            let vb = self.upload(bytemuck::cast_slice(&mesh.positions), input)?;
            let ib = self.upload(bytemuck::cast_slice(&mesh.indices), input)?;
            let tri = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
                .vertex_format(vk::Format::R32G32B32_SFLOAT)
                .vertex_data(vk::DeviceOrHostAddressConstKHR {
                    device_address: self.buffers[vb].addr,
                })
                .vertex_stride(12)
                .max_vertex(mesh.positions.len() as u32 - 1)
                .index_type(vk::IndexType::UINT32)
                .index_data(vk::DeviceOrHostAddressConstKHR {
                    device_address: self.buffers[ib].addr,
                });
            let geom = vk::AccelerationStructureGeometryKHR::default()
                .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
                .geometry(vk::AccelerationStructureGeometryDataKHR { triangles: tri })
                .flags(vk::GeometryFlagsKHR::OPAQUE);
            let (_, addr) =
                self.build(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL, geom, prims)?;
            blas_addr[mi] = Some(addr);
        }
        let mut instances: Vec<u8> = Vec::new();
        for (i, inst) in scene.instances.iter().enumerate() {
            let Some(Some(addr)) = blas_addr.get(inst.mesh as usize) else {
                return Err(format!("instance {i} has a mesh without triangles").into());
            };
            let m = inst.transform;
            let mut rows = [0f32; 12];
            for r in 0..3 {
                for c in 0..4 {
                    rows[r * 4 + c] = m.col(c)[r];
                }
            }
            let record = vk::AccelerationStructureInstanceKHR {
                transform: vk::TransformMatrixKHR { matrix: rows },
                instance_custom_index_and_mask: vk::Packed24_8::new(i as u32, 0xff),
                instance_shader_binding_table_record_offset_and_flags: vk::Packed24_8::new(
                    0,
                    vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE.as_raw() as u8,
                ),
                acceleration_structure_reference: vk::AccelerationStructureReferenceKHR {
                    device_handle: *addr,
                },
            };
            // SAFETY: a plain repr(C) record of 64 bytes, read as bytes.
            let bytes = unsafe {
                std::slice::from_raw_parts(
                    (&record as *const vk::AccelerationStructureInstanceKHR) as *const u8,
                    std::mem::size_of::<vk::AccelerationStructureInstanceKHR>(),
                )
            };
            instances.extend_from_slice(bytes);
        }
        let ibuf = self.upload(&instances, input)?;
        let data = vk::AccelerationStructureGeometryInstancesDataKHR::default().data(
            vk::DeviceOrHostAddressConstKHR {
                device_address: self.buffers[ibuf].addr,
            },
        );
        let geom = vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::INSTANCES)
            .geometry(vk::AccelerationStructureGeometryDataKHR { instances: data });
        let (tlas, _) = self.build(
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            geom,
            scene.instances.len() as u32,
        )?;
        Ok(tlas)
    }

    pub fn host_buffer(&mut self, bytes: u64) -> Res<usize> {
        self.buffer(bytes, vk::BufferUsageFlags::STORAGE_BUFFER, true)
    }

    pub fn kernel(
        &self,
        spirv: &[u32],
        tlas: vk::AccelerationStructureKHR,
        rays: usize,
        hits: usize,
    ) -> Res<Kernel> {
        Kernel::new(
            self,
            spirv,
            tlas,
            self.buffers[rays].buffer,
            self.buffers[hits].buffer,
        )
    }
}

impl Drop for RqDevice {
    fn drop(&mut self) {
        // SAFETY: nothing is in flight (every submission was waited on); children first.
        unsafe {
            let _ = self.device.device_wait_idle();
            for s in self.structures.drain(..) {
                self.asx.destroy_acceleration_structure(s, None);
            }
            for b in self.buffers.drain(..) {
                self.device.destroy_buffer(b.buffer, None);
                self.device.free_memory(b.memory, None);
            }
            self.device.destroy_command_pool(self.pool, None);
            self.device.destroy_device(None);
            self.instance.destroy_instance(None);
        }
    }
}

/// The compute pipeline of kernel.wgsl with its one descriptor set bound to the TLAS, the
/// rays and the hits.
pub struct Kernel {
    device: ash::Device,
    layout: vk::DescriptorSetLayout,
    pipeline_layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
}

impl Kernel {
    fn new(
        rq: &RqDevice,
        spirv: &[u32],
        tlas: vk::AccelerationStructureKHR,
        rays: vk::Buffer,
        hits: vk::Buffer,
    ) -> Res<Kernel> {
        let d = rq.device.clone();
        // SAFETY: handles of this device; the set is written before any dispatch uses it.
        unsafe {
            let binding = |b: u32, ty| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(ty)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            };
            let bindings = [
                binding(0, vk::DescriptorType::ACCELERATION_STRUCTURE_KHR),
                binding(1, vk::DescriptorType::STORAGE_BUFFER),
                binding(2, vk::DescriptorType::STORAGE_BUFFER),
            ];
            let layout = d.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                None,
            )?;
            let push = [vk::PushConstantRange::default()
                .stage_flags(vk::ShaderStageFlags::COMPUTE)
                .size(16)];
            let layouts = [layout];
            let pipeline_layout = d.create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default()
                    .set_layouts(&layouts)
                    .push_constant_ranges(&push),
                None,
            )?;
            let module =
                d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(spirv), None)?;
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main");
            let pipeline = d
                .create_compute_pipelines(
                    vk::PipelineCache::null(),
                    &[vk::ComputePipelineCreateInfo::default()
                        .stage(stage)
                        .layout(pipeline_layout)],
                    None,
                )
                .map_err(|(_, e)| e)?[0];
            d.destroy_shader_module(module, None);
            let sizes = [
                vk::DescriptorPoolSize::default()
                    .ty(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
                    .descriptor_count(1),
                vk::DescriptorPoolSize::default()
                    .ty(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(2),
            ];
            let pool = d.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default()
                    .max_sets(1)
                    .pool_sizes(&sizes),
                None,
            )?;
            let set = d.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default()
                    .descriptor_pool(pool)
                    .set_layouts(&layouts),
            )?[0];
            let structures = [tlas];
            let mut as_write = vk::WriteDescriptorSetAccelerationStructureKHR::default()
                .acceleration_structures(&structures);
            let mut w0 = vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(0)
                .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
                .push_next(&mut as_write);
            w0.descriptor_count = 1;
            let ri = [vk::DescriptorBufferInfo::default()
                .buffer(rays)
                .range(vk::WHOLE_SIZE)];
            let hi = [vk::DescriptorBufferInfo::default()
                .buffer(hits)
                .range(vk::WHOLE_SIZE)];
            let w1 = vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(1)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(&ri);
            let w2 = vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(2)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(&hi);
            d.update_descriptor_sets(&[w0, w1, w2], &[]);
            Ok(Kernel {
                device: d,
                layout,
                pipeline_layout,
                pipeline,
                pool,
                set,
            })
        }
    }

    pub fn record(&self, cmd: vk::CommandBuffer, count: u32) {
        // SAFETY: a recording command buffer of the same device.
        unsafe {
            let d = &self.device;
            d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            d.cmd_bind_descriptor_sets(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                self.pipeline_layout,
                0,
                &[self.set],
                &[],
            );
            let push = [count, 0, 0, 0];
            d.cmd_push_constants(
                cmd,
                self.pipeline_layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                bytemuck::cast_slice(&push),
            );
            d.cmd_dispatch(cmd, count.div_ceil(64), 1, 1);
        }
    }
}

impl Drop for Kernel {
    fn drop(&mut self) {
        // SAFETY: every dispatch was waited on.
        unsafe {
            self.device.destroy_descriptor_pool(self.pool, None);
            self.device.destroy_pipeline(self.pipeline, None);
            self.device
                .destroy_pipeline_layout(self.pipeline_layout, None);
            self.device.destroy_descriptor_set_layout(self.layout, None);
        }
    }
}
