//! Instance, physical-device choice, logical device, compute queue and command submission.

use std::ffi::CStr;
use std::sync::{Arc, Mutex, MutexGuard};

use ash::vk;

use super::{vk_err, DeviceInfo, DeviceRequest, VulkanError};

/// naga emits SPIR-V 1.3, which Vulkan 1.1 is the first to accept.
const MIN_API: u32 = vk::API_VERSION_1_1;
/// Newer versions add nothing the integrator uses; asking for more than the loader knows fails.
const MAX_API: u32 = vk::API_VERSION_1_3;

/// The queue and the command pool share one lock: both must be externally synchronized, and
/// every submission touches both.
struct Submitter {
    queue: vk::Queue,
    pool: vk::CommandPool,
}

/// One open Vulkan device with its compute queue; shared by buffers and kernels through `Arc`.
pub struct GpuContext {
    // Kept only so the loader library stays loaded while the instance and device live.
    _entry: ash::Entry,
    instance: ash::Instance,
    device: ash::Device,
    submitter: Mutex<Submitter>,
    memory: vk::PhysicalDeviceMemoryProperties,
    limits: vk::PhysicalDeviceLimits,
    subgroup: vk::PhysicalDeviceSubgroupProperties<'static>,
    info: DeviceInfo,
    cpu: bool,
    force_staging: bool,
}

/// Set to 1 to move every buffer transfer through staging copies even where device memory is
/// mappable, so CPU-only CI exercises the path discrete GPUs take.
pub const FORCE_STAGING_ENV: &str = "LIGHTFARM_VULKAN_FORCE_STAGING";

/// A physical device that passed the checks, with what choosing and opening it needs.
struct Candidate {
    handle: vk::PhysicalDevice,
    info: DeviceInfo,
    rank: u8,
    uuid: [u8; 16],
    queue_family: u32,
    api: u32,
}

/// Lists every usable device in the same order `DeviceRequest::Index` uses.
pub fn list_devices() -> Result<Vec<DeviceInfo>, VulkanError> {
    let (entry, instance, api) = open_instance()?;
    let listed = enumerate(&instance, api).map(|c| c.into_iter().map(|c| c.info).collect());
    // SAFETY: nothing created from this instance outlives this function.
    unsafe { instance.destroy_instance(None) };
    drop(entry);
    listed
}

impl GpuContext {
    /// Auto: the first discrete GPU, else integrated, else virtual, else CPU (lavapipe).
    /// Gpu: error if none is a GPU. Cpu: the CPU device.
    pub fn new(request: &DeviceRequest) -> Result<Arc<GpuContext>, VulkanError> {
        let (entry, instance, api) = open_instance()?;
        let opened = enumerate(&instance, api)
            .and_then(|candidates| choose(candidates, request))
            .and_then(|chosen| open_device(&instance, &chosen).map(|opened| (chosen, opened)));
        let (chosen, (device, submitter)) = match opened {
            Ok(v) => v,
            Err(e) => {
                // SAFETY: the device was not created (or was destroyed by open_device).
                unsafe { instance.destroy_instance(None) };
                return Err(e);
            }
        };
        // SAFETY: the handle came from this instance; every device here has Vulkan 1.1, which
        // defines the subgroup properties.
        let (memory, properties, subgroup) = unsafe {
            let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut subgroup);
            instance.get_physical_device_properties2(chosen.handle, &mut p2);
            let properties = p2.properties;
            (
                instance.get_physical_device_memory_properties(chosen.handle),
                properties,
                vk::PhysicalDeviceSubgroupProperties {
                    p_next: std::ptr::null_mut(),
                    ..subgroup
                },
            )
        };
        let force_staging = std::env::var(FORCE_STAGING_ENV).is_ok_and(|v| v == "1");
        tracing::info!(
            device = %chosen.info.name,
            kind = %chosen.info.kind,
            driver = %chosen.info.driver,
            api = %chosen.info.api_version,
            max_storage_buffer_range = properties.limits.max_storage_buffer_range,
            force_staging,
            "opened Vulkan device"
        );
        Ok(Arc::new(GpuContext {
            _entry: entry,
            instance,
            device,
            submitter: Mutex::new(submitter),
            memory,
            limits: properties.limits,
            subgroup,
            cpu: chosen.info.kind == "cpu",
            info: chosen.info,
            force_staging,
        }))
    }

    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// The largest buffer a shader may bind, in bytes (128 MiB on lavapipe).
    pub fn max_storage_buffer_range(&self) -> u64 {
        u64::from(self.limits.max_storage_buffer_range)
    }

    /// Whether compute shaders may use the subgroup operations the traversal counters' kernel
    /// uses (ballot and arithmetic, optional in Vulkan 1.1; every desktop driver has them).
    pub fn has_subgroup_counting(&self) -> bool {
        let ops = vk::SubgroupFeatureFlags::BALLOT | vk::SubgroupFeatureFlags::ARITHMETIC;
        self.subgroup
            .supported_stages
            .contains(vk::ShaderStageFlags::COMPUTE)
            && self.subgroup.supported_operations.contains(ops)
    }

    /// Whether this is a CPU implementation, where dispatches are orders of magnitude slower.
    pub fn is_cpu(&self) -> bool {
        self.cpu
    }

    /// Whether buffers must avoid direct mapping (see [`FORCE_STAGING_ENV`]).
    pub(crate) fn force_staging(&self) -> bool {
        self.force_staging
    }

    pub(crate) fn device(&self) -> &ash::Device {
        &self.device
    }

    pub(crate) fn memory_properties(&self) -> &vk::PhysicalDeviceMemoryProperties {
        &self.memory
    }

    pub(crate) fn limits(&self) -> &vk::PhysicalDeviceLimits {
        &self.limits
    }

    fn lock_submitter(&self) -> MutexGuard<'_, Submitter> {
        // A panic while recording cannot leave the queue or pool inconsistent on the Vulkan side,
        // so a poisoned lock is still safe to use.
        self.submitter.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Records commands with `record`, submits them and blocks until the device has finished.
    ///
    /// Barriers around the recorded commands order them after all earlier submissions and make
    /// their writes visible to the host: a fence alone makes no memory visible.
    pub(crate) fn submit_and_wait(
        &self,
        what: &'static str,
        record: impl FnOnce(&ash::Device, vk::CommandBuffer),
    ) -> Result<(), VulkanError> {
        let device = &self.device;
        // SAFETY: every handle used below belongs to this device; the pool and queue are only
        // touched under the submitter lock.
        unsafe {
            let fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .map_err(vk_err("vkCreateFence"))?;
            let guard = self.lock_submitter();
            let alloc = vk::CommandBufferAllocateInfo::default()
                .command_pool(guard.pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            let cmd = match device.allocate_command_buffers(&alloc) {
                Ok(buffers) if !buffers.is_empty() => buffers[0],
                Ok(_) => {
                    drop(guard);
                    device.destroy_fence(fence, None);
                    return Err(vk_err("vkAllocateCommandBuffers")(
                        vk::Result::ERROR_UNKNOWN,
                    ));
                }
                Err(code) => {
                    drop(guard);
                    device.destroy_fence(fence, None);
                    return Err(vk_err("vkAllocateCommandBuffers")(code));
                }
            };
            let submitted = self.record_and_submit(&guard, cmd, fence, record);
            if let Err(e) = submitted {
                device.free_command_buffers(guard.pool, &[cmd]);
                drop(guard);
                device.destroy_fence(fence, None);
                return Err(e);
            }
            drop(guard);

            tracing::trace!(what, "waiting for submission");
            if let Err(code) = device.wait_for_fences(&[fence], true, u64::MAX) {
                // The command buffer may still be pending (device lost): leaking it and the
                // fence is the only safe choice; destroying the device reclaims them.
                return Err(vk_err(what)(code));
            }
            let guard = self.lock_submitter();
            device.free_command_buffers(guard.pool, &[cmd]);
            drop(guard);
            device.destroy_fence(fence, None);
        }
        Ok(())
    }

    /// # Safety
    /// `cmd` must be a fresh primary command buffer from `guard.pool`, `fence` unsignalled.
    unsafe fn record_and_submit(
        &self,
        guard: &Submitter,
        cmd: vk::CommandBuffer,
        fence: vk::Fence,
        record: impl FnOnce(&ash::Device, vk::CommandBuffer),
    ) -> Result<(), VulkanError> {
        let device = &self.device;
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        device
            .begin_command_buffer(cmd, &begin)
            .map_err(vk_err("vkBeginCommandBuffer"))?;
        let work = vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER;
        let before = vk::MemoryBarrier::default()
            .src_access_mask(
                vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::TRANSFER_WRITE
                    | vk::AccessFlags::HOST_WRITE,
            )
            .dst_access_mask(
                vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::TRANSFER_READ
                    | vk::AccessFlags::TRANSFER_WRITE,
            );
        device.cmd_pipeline_barrier(
            cmd,
            work | vk::PipelineStageFlags::HOST,
            work,
            vk::DependencyFlags::empty(),
            &[before],
            &[],
            &[],
        );
        record(device, cmd);
        let after = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        device.cmd_pipeline_barrier(
            cmd,
            work,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &[after],
            &[],
            &[],
        );
        device
            .end_command_buffer(cmd)
            .map_err(vk_err("vkEndCommandBuffer"))?;
        let cmds = [cmd];
        let submit = vk::SubmitInfo::default().command_buffers(&cmds);
        device
            .queue_submit(guard.queue, &[submit], fence)
            .map_err(vk_err("vkQueueSubmit"))
    }
}

impl Drop for GpuContext {
    fn drop(&mut self) {
        // SAFETY: buffers and kernels hold an Arc to this context, so none is left; waiting for
        // idle covers a submission abandoned after a failed fence wait.
        unsafe {
            if let Err(code) = self.device.device_wait_idle() {
                tracing::warn!(%code, "vkDeviceWaitIdle failed while closing the device");
            }
            let pool = self.lock_submitter().pool;
            self.device.destroy_command_pool(pool, None);
            self.device.destroy_device(None);
            self.instance.destroy_instance(None);
        }
        tracing::debug!(device = %self.info.name, "closed Vulkan device");
    }
}

fn open_instance() -> Result<(ash::Entry, ash::Instance, u32), VulkanError> {
    // SAFETY: loading the system loader runs its initializers, which is what it is for.
    let entry = unsafe { ash::Entry::load() }.map_err(|e| VulkanError::LoaderMissing {
        detail: e.to_string(),
    })?;
    // SAFETY: plain query on a loaded entry. `None` means a Vulkan 1.0 loader.
    let loader = unsafe { entry.try_enumerate_instance_version() }
        .map_err(vk_err("vkEnumerateInstanceVersion"))?
        .unwrap_or(vk::API_VERSION_1_0);
    if loader < MIN_API {
        tracing::warn!(
            loader = %version_string(loader),
            "the Vulkan loader is older than 1.1"
        );
        return Err(VulkanError::NoDevice);
    }
    let api = loader.min(MAX_API);
    let app = vk::ApplicationInfo::default()
        .application_name(c"lightfarm")
        .engine_name(c"lightfarm")
        .api_version(api);
    let create = vk::InstanceCreateInfo::default().application_info(&app);
    // SAFETY: the create info only borrows locals that outlive the call.
    let instance = unsafe { entry.create_instance(&create, None) }.map_err(|code| match code {
        // No installable client driver at all: the same fix as having no device.
        vk::Result::ERROR_INCOMPATIBLE_DRIVER => VulkanError::NoDevice,
        code => vk_err("vkCreateInstance")(code),
    })?;
    Ok((entry, instance, api))
}

/// Every physical device that can run naga's SPIR-V, sorted GPUs first, then by name and UUID,
/// so that indices stay stable across runs whatever order the loader reports.
fn enumerate(instance: &ash::Instance, instance_api: u32) -> Result<Vec<Candidate>, VulkanError> {
    // SAFETY: plain queries on a live instance.
    let handles = unsafe { instance.enumerate_physical_devices() }
        .map_err(vk_err("vkEnumeratePhysicalDevices"))?;
    let mut candidates = Vec::new();
    for handle in handles {
        if let Some(c) = describe(instance, instance_api, handle) {
            candidates.push(c);
        }
    }
    candidates.sort_by(|a, b| {
        a.rank
            .cmp(&b.rank)
            .then_with(|| a.info.name.cmp(&b.info.name))
            .then_with(|| a.uuid.cmp(&b.uuid))
    });
    for (index, c) in candidates.iter_mut().enumerate() {
        c.info.index = index;
    }
    if candidates.is_empty() {
        return Err(VulkanError::NoDevice);
    }
    Ok(candidates)
}

fn describe(
    instance: &ash::Instance,
    instance_api: u32,
    handle: vk::PhysicalDevice,
) -> Option<Candidate> {
    // SAFETY: queries on a handle enumerated from this instance; the pNext chain only borrows
    // locals, and the driver-properties struct is chained only where Vulkan 1.2 defines it.
    unsafe {
        let props = instance.get_physical_device_properties(handle);
        let name = cstr(props.device_name_as_c_str());
        let api = props.api_version.min(instance_api);
        if api < MIN_API {
            tracing::debug!(%name, "skipping device older than Vulkan 1.1");
            return None;
        }
        let families = instance.get_physical_device_queue_family_properties(handle);
        let Some(queue_family) = families
            .iter()
            .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE) && f.queue_count > 0)
        else {
            tracing::debug!(%name, "skipping device without a compute queue");
            return None;
        };
        let mut id = vk::PhysicalDeviceIDProperties::default();
        let mut driver_props = vk::PhysicalDeviceDriverProperties::default();
        let driver = if api >= vk::API_VERSION_1_2 {
            let mut p2 = vk::PhysicalDeviceProperties2::default()
                .push_next(&mut id)
                .push_next(&mut driver_props);
            instance.get_physical_device_properties2(handle, &mut p2);
            let driver_name = cstr(driver_props.driver_name_as_c_str());
            let driver_info = cstr(driver_props.driver_info_as_c_str());
            if driver_info.is_empty() {
                driver_name
            } else {
                format!("{driver_name} ({driver_info})")
            }
        } else {
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut id);
            instance.get_physical_device_properties2(handle, &mut p2);
            format!("driver version {:#x}", props.driver_version)
        };
        let (rank, kind) = match props.device_type {
            vk::PhysicalDeviceType::DISCRETE_GPU => (0, "discrete-gpu"),
            vk::PhysicalDeviceType::INTEGRATED_GPU => (1, "integrated-gpu"),
            vk::PhysicalDeviceType::VIRTUAL_GPU => (2, "virtual-gpu"),
            vk::PhysicalDeviceType::CPU => (3, "cpu"),
            _ => (4, "other"),
        };
        Some(Candidate {
            handle,
            info: DeviceInfo {
                index: 0,
                name,
                kind: kind.to_string(),
                driver,
                api_version: version_string(props.api_version),
            },
            rank,
            uuid: id.device_uuid,
            queue_family: u32::try_from(queue_family).ok()?,
            api,
        })
    }
}

fn choose(candidates: Vec<Candidate>, request: &DeviceRequest) -> Result<Candidate, VulkanError> {
    let available = candidates
        .iter()
        .map(|c| format!("[{}] {} ({})", c.info.index, c.info.name, c.info.kind))
        .collect::<Vec<_>>()
        .join(", ");
    let chosen = match request {
        // Sorted by kind already: the first device is the best one.
        DeviceRequest::Auto => candidates.into_iter().next(),
        DeviceRequest::Gpu => candidates.into_iter().find(|c| c.info.is_gpu()),
        DeviceRequest::Cpu => candidates.into_iter().find(|c| c.info.kind == "cpu"),
        DeviceRequest::Index(i) => candidates.into_iter().nth(*i),
        DeviceRequest::Name(name) => {
            let needle = name.to_lowercase();
            candidates
                .into_iter()
                .find(|c| c.info.name.to_lowercase().contains(&needle))
        }
    };
    chosen.ok_or_else(|| VulkanError::DeviceNotFound {
        request: request.to_string(),
        available,
    })
}

/// Creates the logical device with one compute queue and the command pool.
fn open_device(
    instance: &ash::Instance,
    chosen: &Candidate,
) -> Result<(ash::Device, Submitter), VulkanError> {
    // SAFETY: the handle belongs to `instance`; feature structs are chained only where the
    // device's Vulkan version defines them, and every pNext pointer outlives the calls.
    unsafe {
        let supported = instance.get_physical_device_features(chosen.handle);
        // Only features naga may need for wider integer/float types, each enabled only where
        // present: requesting an unsupported feature fails device creation.
        let core = vk::PhysicalDeviceFeatures::default()
            .shader_float64(supported.shader_float64 == vk::TRUE)
            .shader_int64(supported.shader_int64 == vk::TRUE)
            .shader_int16(supported.shader_int16 == vk::TRUE);
        let mut have12 = vk::PhysicalDeviceVulkan12Features::default();
        let chain12 = chosen.api >= vk::API_VERSION_1_2;
        if chain12 {
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut have12);
            instance.get_physical_device_features2(chosen.handle, &mut f2);
        }
        let mut want12 = vk::PhysicalDeviceVulkan12Features::default()
            .shader_float16(have12.shader_float16 == vk::TRUE)
            .shader_int8(have12.shader_int8 == vk::TRUE)
            .shader_buffer_int64_atomics(have12.shader_buffer_int64_atomics == vk::TRUE)
            .scalar_block_layout(have12.scalar_block_layout == vk::TRUE)
            .uniform_buffer_standard_layout(have12.uniform_buffer_standard_layout == vk::TRUE);

        let priorities = [1.0f32];
        let queues = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(chosen.queue_family)
            .queue_priorities(&priorities)];
        let mut create = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queues)
            .enabled_features(&core);
        if chain12 {
            create = create.push_next(&mut want12);
        }
        let device = instance
            .create_device(chosen.handle, &create, None)
            .map_err(vk_err("vkCreateDevice"))?;
        let queue = device.get_device_queue(chosen.queue_family, 0);
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(chosen.queue_family)
            .flags(vk::CommandPoolCreateFlags::TRANSIENT);
        let pool = match device.create_command_pool(&pool_info, None) {
            Ok(pool) => pool,
            Err(code) => {
                device.destroy_device(None);
                return Err(vk_err("vkCreateCommandPool")(code));
            }
        };
        Ok((device, Submitter { queue, pool }))
    }
}

fn cstr<E>(name: Result<&CStr, E>) -> String {
    name.map(|c| c.to_string_lossy().into_owned())
        .unwrap_or_else(|_| "<unnamed>".to_string())
}

fn version_string(v: u32) -> String {
    format!(
        "{}.{}.{}",
        vk::api_version_major(v),
        vk::api_version_minor(v),
        vk::api_version_patch(v)
    )
}
