//! Compute kernels: a SPIR-V module whose bindings 0..n-1 in set 0 are storage buffers or
//! record images ([`GpuImage`]), plus an optional push-constant block, dispatched synchronously.

use std::sync::Arc;

use ash::vk;

use super::{vk_err, GpuBuffer, GpuContext, GpuImage, VulkanError};

/// What a binding of a kernel is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    StorageBuffer,
    /// A storage image read with `textureLoad` (a [`GpuImage`]).
    Image,
}

impl BindingKind {
    fn descriptor(self) -> vk::DescriptorType {
        match self {
            BindingKind::StorageBuffer => vk::DescriptorType::STORAGE_BUFFER,
            BindingKind::Image => vk::DescriptorType::STORAGE_IMAGE,
        }
    }
}

/// What is bound at one binding of a dispatch.
#[derive(Clone, Copy, Debug)]
pub enum Resource<'a> {
    Buffer(&'a GpuBuffer),
    Image(&'a GpuImage),
}

impl Resource<'_> {
    fn kind(&self) -> BindingKind {
        match self {
            Resource::Buffer(_) => BindingKind::StorageBuffer,
            Resource::Image(_) => BindingKind::Image,
        }
    }

    fn label(&self) -> &str {
        match self {
            Resource::Buffer(b) => b.label(),
            Resource::Image(i) => i.label(),
        }
    }

    fn context(&self) -> &Arc<GpuContext> {
        match self {
            Resource::Buffer(b) => b.context(),
            Resource::Image(i) => i.context(),
        }
    }
}

/// A compute pipeline ready to dispatch; the entry point is always `main`.
pub struct ComputeKernel {
    ctx: Arc<GpuContext>,
    label: String,
    bindings: Vec<BindingKind>,
    push_constant_bytes: u32,
    module: vk::ShaderModule,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

/// The Vulkan objects created so far while building a kernel; whatever is not null is destroyed
/// on drop, so every early return cleans up.
struct Parts<'a> {
    device: &'a ash::Device,
    module: vk::ShaderModule,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

impl Drop for Parts<'_> {
    fn drop(&mut self) {
        // SAFETY: null handles are ignored by vkDestroy*; none of these was ever submitted
        // (a kernel takes them out before it can be dispatched).
        unsafe {
            self.device.destroy_pipeline(self.pipeline, None);
            self.device.destroy_pipeline_layout(self.layout, None);
            self.device
                .destroy_descriptor_set_layout(self.set_layout, None);
            self.device.destroy_shader_module(self.module, None);
        }
    }
}

impl ComputeKernel {
    /// A kernel whose `num_bindings` bindings are all storage buffers.
    pub fn new(
        ctx: &Arc<GpuContext>,
        label: &str,
        spirv: &[u32],
        num_bindings: u32,
        push_constant_bytes: u32,
    ) -> Result<ComputeKernel, VulkanError> {
        let kinds = vec![BindingKind::StorageBuffer; num_bindings as usize];
        Self::with_bindings(ctx, label, spirv, &kinds, push_constant_bytes)
    }

    /// A kernel with binding i of kind `bindings[i]`.
    pub fn with_bindings(
        ctx: &Arc<GpuContext>,
        label: &str,
        spirv: &[u32],
        bindings: &[BindingKind],
        push_constant_bytes: u32,
    ) -> Result<ComputeKernel, VulkanError> {
        if spirv.is_empty() {
            return Err(VulkanError::EmptySpirv {
                kernel: label.to_string(),
            });
        }
        let limit = ctx.limits().max_push_constants_size;
        if push_constant_bytes > limit || push_constant_bytes & 3 != 0 {
            return Err(VulkanError::PushConstantsTooLarge {
                kernel: label.to_string(),
                bytes: push_constant_bytes,
                limit,
            });
        }
        let device = ctx.device();
        let mut parts = Parts {
            device,
            module: vk::ShaderModule::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
        };
        let kinds = bindings;
        let bindings: Vec<_> = kinds
            .iter()
            .zip(0u32..)
            .map(|(kind, binding)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(binding)
                    .descriptor_type(kind.descriptor())
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .offset(0)
            .size(push_constant_bytes)];
        let ranges: &[vk::PushConstantRange] = if push_constant_bytes > 0 {
            &ranges
        } else {
            &[]
        };
        // SAFETY: create infos only borrow locals; `parts` destroys whatever was made if a
        // later step fails.
        unsafe {
            parts.module = device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(spirv), None)
                .map_err(vk_err("vkCreateShaderModule"))?;
            parts.set_layout = device
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )
                .map_err(vk_err("vkCreateDescriptorSetLayout"))?;
            let set_layouts = [parts.set_layout];
            parts.layout = device
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default()
                        .set_layouts(&set_layouts)
                        .push_constant_ranges(ranges),
                    None,
                )
                .map_err(vk_err("vkCreatePipelineLayout"))?;
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(parts.module)
                .name(c"main");
            let info = vk::ComputePipelineCreateInfo::default()
                .stage(stage)
                .layout(parts.layout);
            let started = std::time::Instant::now();
            let pipelines = device
                .create_compute_pipelines(vk::PipelineCache::null(), &[info], None)
                .map_err(|(_, code)| vk_err("vkCreateComputePipelines")(code))?;
            parts.pipeline = pipelines.first().copied().unwrap_or_default();
            if parts.pipeline == vk::Pipeline::null() {
                return Err(vk_err("vkCreateComputePipelines")(
                    vk::Result::ERROR_UNKNOWN,
                ));
            }
            tracing::debug!(
                kernel = label,
                ms = started.elapsed().as_secs_f64() * 1e3,
                "compiled compute pipeline"
            );
        }
        let kernel = ComputeKernel {
            ctx: Arc::clone(ctx),
            label: label.to_string(),
            bindings: kinds.to_vec(),
            push_constant_bytes,
            // Taking the handles leaves nulls behind, which disarms the cleanup guard.
            module: std::mem::take(&mut parts.module),
            set_layout: std::mem::take(&mut parts.set_layout),
            layout: std::mem::take(&mut parts.layout),
            pipeline: std::mem::take(&mut parts.pipeline),
        };
        Ok(kernel)
    }

    /// Binds `buffers[i]` at binding i (a kernel of storage buffers only), pushes
    /// `push_constants`, dispatches `groups` and waits for the device to finish.
    pub fn dispatch(
        &self,
        buffers: &[&GpuBuffer],
        push_constants: &[u8],
        groups: [u32; 3],
    ) -> Result<(), VulkanError> {
        let resources: Vec<Resource> = buffers.iter().map(|b| Resource::Buffer(b)).collect();
        self.dispatch_resources(&resources, push_constants, groups)
    }

    /// Binds `resources[i]` at binding i, pushes `push_constants`, dispatches `groups` and
    /// waits for the device to finish.
    pub fn dispatch_resources(
        &self,
        resources: &[Resource],
        push_constants: &[u8],
        groups: [u32; 3],
    ) -> Result<(), VulkanError> {
        self.check(resources, push_constants, groups)?;
        if groups.contains(&0) {
            return Ok(());
        }
        let device = self.ctx.device();
        // A pool per call: descriptor sets then never outlive the buffers they point at, and
        // the cost is negligible next to a dispatch.
        let pool = if !self.bindings.is_empty() {
            let sizes: Vec<_> = [BindingKind::StorageBuffer, BindingKind::Image]
                .into_iter()
                .map(|kind| {
                    let n = self.bindings.iter().filter(|k| **k == kind).count();
                    vk::DescriptorPoolSize::default()
                        .ty(kind.descriptor())
                        .descriptor_count(n as u32)
                })
                .filter(|s| s.descriptor_count > 0)
                .collect();
            let info = vk::DescriptorPoolCreateInfo::default()
                .max_sets(1)
                .pool_sizes(&sizes);
            // SAFETY: the create info only borrows locals.
            Some(
                unsafe { device.create_descriptor_pool(&info, None) }
                    .map_err(vk_err("vkCreateDescriptorPool"))?,
            )
        } else {
            None
        };
        let result = self.dispatch_with(pool, resources, push_constants, groups);
        if let Some(pool) = pool {
            // SAFETY: the submission using the set has completed (or never happened); a failed
            // wait is a lost device, where destroying is still allowed.
            unsafe { device.destroy_descriptor_pool(pool, None) };
        }
        result
    }

    fn check(
        &self,
        resources: &[Resource],
        push_constants: &[u8],
        groups: [u32; 3],
    ) -> Result<(), VulkanError> {
        if resources.len() != self.bindings.len() {
            return Err(VulkanError::BindingCountMismatch {
                kernel: self.label.clone(),
                expected: self.bindings.len() as u32,
                got: resources.len(),
            });
        }
        if let Some((binding, r)) = resources
            .iter()
            .zip(&self.bindings)
            .enumerate()
            .find_map(|(i, (r, kind))| (r.kind() != *kind).then_some((i, r)))
        {
            return Err(VulkanError::BindingKindMismatch {
                kernel: self.label.clone(),
                binding: binding as u32,
                expected: format!("{:?}", self.bindings[binding]),
                got: r.label().to_string(),
            });
        }
        if push_constants.len() != self.push_constant_bytes as usize {
            return Err(VulkanError::PushConstantSizeMismatch {
                kernel: self.label.clone(),
                expected: self.push_constant_bytes,
                got: push_constants.len(),
            });
        }
        if let Some(foreign) = resources
            .iter()
            .find(|b| !Arc::ptr_eq(b.context(), &self.ctx))
        {
            return Err(VulkanError::ForeignBuffer {
                kernel: self.label.clone(),
                buffer: foreign.label().to_string(),
            });
        }
        let limit = self.ctx.limits().max_compute_work_group_count;
        if groups.iter().zip(limit).any(|(g, l)| *g > l) {
            return Err(VulkanError::DispatchTooLarge {
                kernel: self.label.clone(),
                groups,
                limit,
            });
        }
        Ok(())
    }

    fn dispatch_with(
        &self,
        pool: Option<vk::DescriptorPool>,
        resources: &[Resource],
        push_constants: &[u8],
        groups: [u32; 3],
    ) -> Result<(), VulkanError> {
        let device = self.ctx.device();
        let mut set = None;
        if let Some(pool) = pool {
            let layouts = [self.set_layout];
            let info = vk::DescriptorSetAllocateInfo::default()
                .descriptor_pool(pool)
                .set_layouts(&layouts);
            // SAFETY: the pool was made for exactly this layout; sets are freed with the pool.
            let sets = unsafe { device.allocate_descriptor_sets(&info) }
                .map_err(vk_err("vkAllocateDescriptorSets"))?;
            let Some(&allocated) = sets.first() else {
                return Err(vk_err("vkAllocateDescriptorSets")(
                    vk::Result::ERROR_UNKNOWN,
                ));
            };
            // One info per binding, of either kind; each write borrows its own.
            let infos: Vec<([vk::DescriptorBufferInfo; 1], [vk::DescriptorImageInfo; 1])> =
                resources
                    .iter()
                    .map(|r| match r {
                        Resource::Buffer(b) => (
                            [vk::DescriptorBufferInfo::default()
                                .buffer(b.raw())
                                .offset(0)
                                .range(vk::WHOLE_SIZE)],
                            [vk::DescriptorImageInfo::default()],
                        ),
                        Resource::Image(i) => (
                            [vk::DescriptorBufferInfo::default()],
                            [vk::DescriptorImageInfo::default()
                                .image_view(i.view())
                                .image_layout(vk::ImageLayout::GENERAL)],
                        ),
                    })
                    .collect();
            let writes: Vec<_> = infos
                .iter()
                .zip(resources)
                .zip(0u32..)
                .map(|(((buffer, image), r), binding)| {
                    let w = vk::WriteDescriptorSet::default()
                        .dst_set(allocated)
                        .dst_binding(binding)
                        .descriptor_type(r.kind().descriptor());
                    match r {
                        Resource::Buffer(_) => w.buffer_info(buffer),
                        Resource::Image(_) => w.image_info(image),
                    }
                })
                .collect();
            // SAFETY: the set is not in use; every buffer is alive for the whole call.
            unsafe { device.update_descriptor_sets(&writes, &[]) };
            set = Some(allocated);
        }
        let started = std::time::Instant::now();
        self.ctx.submit_and_wait("vkCmdDispatch", |device, cmd| {
            // SAFETY: `cmd` is recording; pipeline, layout and set belong to this device.
            unsafe {
                device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
                if let Some(set) = set {
                    device.cmd_bind_descriptor_sets(
                        cmd,
                        vk::PipelineBindPoint::COMPUTE,
                        self.layout,
                        0,
                        &[set],
                        &[],
                    );
                }
                if !push_constants.is_empty() {
                    device.cmd_push_constants(
                        cmd,
                        self.layout,
                        vk::ShaderStageFlags::COMPUTE,
                        0,
                        push_constants,
                    );
                }
                device.cmd_dispatch(cmd, groups[0], groups[1], groups[2]);
            }
        })?;
        tracing::trace!(
            kernel = %self.label,
            ?groups,
            ms = started.elapsed().as_secs_f64() * 1e3,
            "dispatch finished"
        );
        Ok(())
    }

    pub fn label(&self) -> &str {
        &self.label
    }
}

impl Drop for ComputeKernel {
    fn drop(&mut self) {
        // SAFETY: dispatches are synchronous, so the pipeline is idle.
        unsafe {
            let device = self.ctx.device();
            device.destroy_pipeline(self.pipeline, None);
            device.destroy_pipeline_layout(self.layout, None);
            device.destroy_descriptor_set_layout(self.set_layout, None);
            device.destroy_shader_module(self.module, None);
        }
    }
}
