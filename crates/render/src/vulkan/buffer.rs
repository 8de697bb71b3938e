//! Storage buffers: device-local memory, filled and read back through staging buffers when the
//! host cannot map that memory (discrete GPUs), mapped directly when it can (lavapipe, iGPUs).

use std::sync::{Arc, Mutex};

use ash::vk;

use super::{vk_err, GpuContext, VulkanError};

/// Vulkan forbids zero-sized buffers; an empty input still gets something bindable.
const EMPTY_BUFFER_BYTES: u64 = 16;

/// A storage buffer on the device, usable at any binding of a [`super::ComputeKernel`].
pub struct GpuBuffer {
    ctx: Arc<GpuContext>,
    label: String,
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    /// Bytes as requested; the VkBuffer may be up to 3 bytes larger (see `padded`).
    size: u64,
    /// Host-visible and coherent: read and written by mapping, no staging copy.
    mappable: bool,
    /// Serializes host access: a memory object may be mapped only once at a time.
    host: Mutex<()>,
}

/// A buffer and its dedicated memory; freed by its owner.
struct Allocation {
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    flags: vk::MemoryPropertyFlags,
}

/// A temporary host-visible buffer, freed when it goes out of scope (errors included).
struct Staging<'a> {
    ctx: &'a GpuContext,
    alloc: Allocation,
    bytes: u64,
}

impl Drop for Staging<'_> {
    fn drop(&mut self) {
        // SAFETY: every submission using it has been waited for before the guard drops.
        unsafe { free(self.ctx, &self.alloc) };
    }
}

impl GpuBuffer {
    /// Device-local storage buffer filled with `data`. Empty data gives a 16-byte zeroed buffer.
    pub fn from_slice<T: bytemuck::Pod>(
        ctx: &Arc<GpuContext>,
        label: &str,
        data: &[T],
    ) -> Result<GpuBuffer, VulkanError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.is_empty() {
            return Self::zeroed(ctx, label, 0);
        }
        let buffer = Self::allocate(ctx, label, bytes.len() as u64)?;
        // Uploading pads the tail to the VkBuffer size with zeros, so no byte is uninitialized.
        buffer.upload(bytes, true)?;
        Ok(buffer)
    }

    /// Device-local storage buffer of `bytes` zero bytes (16 when `bytes` is 0).
    pub fn zeroed(
        ctx: &Arc<GpuContext>,
        label: &str,
        bytes: u64,
    ) -> Result<GpuBuffer, VulkanError> {
        let bytes = if bytes == 0 {
            EMPTY_BUFFER_BYTES
        } else {
            bytes
        };
        let buffer = Self::allocate(ctx, label, bytes)?;
        if buffer.mappable {
            buffer.with_mapped(|ptr, len| {
                // SAFETY: `ptr` maps `len` bytes of this buffer's memory.
                unsafe { std::ptr::write_bytes(ptr, 0, len) }
            })?;
        } else {
            let target = buffer.buffer;
            ctx.submit_and_wait("vkCmdFillBuffer", |device, cmd| {
                // SAFETY: `cmd` is recording; WHOLE_SIZE covers the padded tail as well.
                unsafe { device.cmd_fill_buffer(cmd, target, 0, vk::WHOLE_SIZE, 0) }
            })?;
        }
        Ok(buffer)
    }

    /// Overwrites the buffer from offset 0 with `data`; bytes past its end stay unchanged.
    ///
    /// The caller must not run a kernel on this buffer concurrently from another thread.
    pub fn write<T: bytemuck::Pod>(&self, data: &[T]) -> Result<(), VulkanError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.len() as u64 > self.size {
            return Err(VulkanError::WriteTooLarge {
                label: self.label.clone(),
                bytes: bytes.len() as u64,
                capacity: self.size,
            });
        }
        if bytes.is_empty() {
            return Ok(());
        }
        self.upload(bytes, false)
    }

    /// The whole buffer as `size / size_of::<T>()` elements (a partial tail element is dropped).
    pub fn read<T: bytemuck::Pod>(&self) -> Result<Vec<T>, VulkanError> {
        let element = std::mem::size_of::<T>() as u64;
        if element == 0 {
            return Ok(Vec::new());
        }
        let count = self.size / element;
        let mut out = vec![T::zeroed(); count as usize];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        if dst.is_empty() {
            return Ok(out);
        }
        if self.mappable {
            self.with_mapped(|ptr, len| {
                let n = dst.len().min(len);
                // SAFETY: `ptr` maps at least `size` bytes, `dst` holds at most `size` bytes.
                unsafe { std::ptr::copy_nonoverlapping(ptr, dst.as_mut_ptr(), n) }
            })?;
            return Ok(out);
        }
        let bytes = dst.len() as u64;
        let staging = Staging::new(
            &self.ctx,
            &self.label,
            bytes,
            vk::BufferUsageFlags::TRANSFER_DST,
            vk::MemoryPropertyFlags::HOST_CACHED,
        )?;
        let (src, target) = (self.buffer, staging.alloc.buffer);
        self.ctx
            .submit_and_wait("vkCmdCopyBuffer (readback)", |device, cmd| {
                let region = vk::BufferCopy::default().size(bytes);
                // SAFETY: `cmd` is recording; both buffers hold at least `bytes` bytes.
                unsafe { device.cmd_copy_buffer(cmd, src, target, &[region]) }
            })?;
        map_memory(
            &self.ctx,
            staging.alloc.memory,
            staging.bytes,
            |ptr, len| {
                let n = dst.len().min(len);
                // SAFETY: the staging memory holds `bytes` == `dst.len()` bytes.
                unsafe { std::ptr::copy_nonoverlapping(ptr, dst.as_mut_ptr(), n) }
            },
        )?;
        Ok(out)
    }

    /// Size in bytes as requested at creation (16 for buffers created empty).
    pub fn size(&self) -> u64 {
        self.size
    }

    pub fn label(&self) -> &str {
        &self.label
    }

    pub(crate) fn raw(&self) -> vk::Buffer {
        self.buffer
    }

    pub(crate) fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    fn allocate(ctx: &Arc<GpuContext>, label: &str, bytes: u64) -> Result<GpuBuffer, VulkanError> {
        let limit = ctx.max_storage_buffer_range();
        // Checked before anything is allocated: the device would accept the allocation and
        // only fail (or silently truncate) when the buffer is bound.
        if bytes > limit {
            return Err(VulkanError::BufferTooLarge {
                label: label.to_string(),
                bytes,
                limit,
            });
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_SRC
            | vk::BufferUsageFlags::TRANSFER_DST;
        // Preferring DEVICE_LOCAL alone picks VRAM on discrete GPUs (the first such type is the
        // fastest one by the spec's ordering rule) and the one unified type on lavapipe.
        let alloc = allocate(
            ctx,
            label,
            padded(bytes),
            usage,
            vk::MemoryPropertyFlags::empty(),
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
        )?;
        let host = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        tracing::debug!(label, bytes, flags = ?alloc.flags, "allocated storage buffer");
        Ok(GpuBuffer {
            ctx: Arc::clone(ctx),
            label: label.to_string(),
            buffer: alloc.buffer,
            memory: alloc.memory,
            size: bytes,
            mappable: alloc.flags.contains(host) && !ctx.force_staging(),
            host: Mutex::new(()),
        })
    }

    /// Copies `bytes` to offset 0; with `pad_tail`, zeroes the rest of the VkBuffer as well.
    fn upload(&self, bytes: &[u8], pad_tail: bool) -> Result<(), VulkanError> {
        if self.mappable {
            return self.with_mapped(|ptr, len| {
                let n = bytes.len().min(len);
                // SAFETY: `ptr` maps `len` bytes; we write `n` <= `len`, then the rest.
                unsafe {
                    std::ptr::copy_nonoverlapping(bytes.as_ptr(), ptr, n);
                    if pad_tail {
                        std::ptr::write_bytes(ptr.add(n), 0, len - n);
                    }
                }
            });
        }
        let copy_len = if pad_tail {
            padded(self.size)
        } else {
            bytes.len() as u64
        };
        let staging = Staging::new(
            &self.ctx,
            &self.label,
            copy_len,
            vk::BufferUsageFlags::TRANSFER_SRC,
            vk::MemoryPropertyFlags::empty(),
        )?;
        map_memory(
            &self.ctx,
            staging.alloc.memory,
            staging.bytes,
            |ptr, len| {
                let n = bytes.len().min(len);
                // SAFETY: the staging memory holds `copy_len` >= `bytes.len()` bytes.
                unsafe {
                    std::ptr::copy_nonoverlapping(bytes.as_ptr(), ptr, n);
                    std::ptr::write_bytes(ptr.add(n), 0, len - n);
                }
            },
        )?;
        let (src, target) = (staging.alloc.buffer, self.buffer);
        self.ctx
            .submit_and_wait("vkCmdCopyBuffer (upload)", |device, cmd| {
                let region = vk::BufferCopy::default().size(copy_len);
                // SAFETY: `cmd` is recording; both buffers hold at least `copy_len` bytes.
                unsafe { device.cmd_copy_buffer(cmd, src, target, &[region]) }
            })
    }

    fn with_mapped<R>(&self, f: impl FnOnce(*mut u8, usize) -> R) -> Result<R, VulkanError> {
        let _host = self.host.lock().unwrap_or_else(|p| p.into_inner());
        map_memory(&self.ctx, self.memory, padded(self.size), f)
    }
}

impl Drop for GpuBuffer {
    fn drop(&mut self) {
        // SAFETY: every submission is waited for before the call that made it returns, so the
        // device no longer uses this buffer.
        unsafe {
            free(
                &self.ctx,
                &Allocation {
                    buffer: self.buffer,
                    memory: self.memory,
                    flags: vk::MemoryPropertyFlags::empty(),
                },
            )
        };
    }
}

impl std::fmt::Debug for GpuBuffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuBuffer")
            .field("label", &self.label)
            .field("size", &self.size)
            .field("mappable", &self.mappable)
            .finish_non_exhaustive()
    }
}

impl<'a> Staging<'a> {
    fn new(
        ctx: &'a GpuContext,
        label: &str,
        bytes: u64,
        usage: vk::BufferUsageFlags,
        preferred: vk::MemoryPropertyFlags,
    ) -> Result<Staging<'a>, VulkanError> {
        let required =
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let alloc = allocate(
            ctx,
            &format!("{label} (staging)"),
            bytes,
            usage,
            required,
            preferred,
        )?;
        Ok(Staging { ctx, alloc, bytes })
    }
}

/// Rounded up to 4 bytes: shaders see storage buffers as arrays of 4-byte words.
fn padded(bytes: u64) -> u64 {
    bytes.div_ceil(4) * 4
}

/// Creates a buffer with its own memory of a type that has `required` flags, preferring one
/// that also has `preferred`.
fn allocate(
    ctx: &GpuContext,
    label: &str,
    bytes: u64,
    usage: vk::BufferUsageFlags,
    required: vk::MemoryPropertyFlags,
    preferred: vk::MemoryPropertyFlags,
) -> Result<Allocation, VulkanError> {
    let device = ctx.device();
    let oom = |code| match code {
        vk::Result::ERROR_OUT_OF_DEVICE_MEMORY | vk::Result::ERROR_OUT_OF_HOST_MEMORY => {
            VulkanError::OutOfMemory {
                label: label.to_string(),
                bytes,
                code,
            }
        }
        code => vk_err("vkCreateBuffer/vkAllocateMemory")(code),
    };
    let info = vk::BufferCreateInfo::default()
        .size(bytes)
        .usage(usage)
        .sharing_mode(vk::SharingMode::EXCLUSIVE);
    // SAFETY: the create infos only borrow locals; on every failure path the objects created so
    // far are destroyed before returning.
    unsafe {
        let buffer = device.create_buffer(&info, None).map_err(oom)?;
        let needs = device.get_buffer_memory_requirements(buffer);
        let Some((type_index, flags)) = memory_type(
            ctx.memory_properties(),
            needs.memory_type_bits,
            required,
            preferred,
        ) else {
            device.destroy_buffer(buffer, None);
            return Err(VulkanError::NoMemoryType {
                label: label.to_string(),
            });
        };
        let alloc_info = vk::MemoryAllocateInfo::default()
            .allocation_size(needs.size)
            .memory_type_index(type_index);
        let memory = match device.allocate_memory(&alloc_info, None) {
            Ok(memory) => memory,
            Err(code) => {
                device.destroy_buffer(buffer, None);
                return Err(oom(code));
            }
        };
        if let Err(code) = device.bind_buffer_memory(buffer, memory, 0) {
            device.destroy_buffer(buffer, None);
            device.free_memory(memory, None);
            return Err(vk_err("vkBindBufferMemory")(code));
        }
        Ok(Allocation {
            buffer,
            memory,
            flags,
        })
    }
}

/// # Safety
/// The device must no longer use the buffer.
unsafe fn free(ctx: &GpuContext, alloc: &Allocation) {
    ctx.device().destroy_buffer(alloc.buffer, None);
    ctx.device().free_memory(alloc.memory, None);
}

pub(super) fn memory_type(
    props: &vk::PhysicalDeviceMemoryProperties,
    type_bits: u32,
    required: vk::MemoryPropertyFlags,
    preferred: vk::MemoryPropertyFlags,
) -> Option<(u32, vk::MemoryPropertyFlags)> {
    let count = (props.memory_type_count as usize).min(props.memory_types.len());
    let usable = |wanted: vk::MemoryPropertyFlags| {
        props.memory_types[..count]
            .iter()
            .enumerate()
            .find(|(i, t)| type_bits & (1 << i) != 0 && t.property_flags.contains(wanted))
            .map(|(i, t)| (i as u32, t.property_flags))
    };
    usable(required | preferred).or_else(|| usable(required))
}

/// Maps the first `len` bytes of the memory object, hands `f` the pointer and length, and
/// unmaps it again.
fn map_memory<R>(
    ctx: &GpuContext,
    memory: vk::DeviceMemory,
    len: u64,
    f: impl FnOnce(*mut u8, usize) -> R,
) -> Result<R, VulkanError> {
    let device = ctx.device();
    // SAFETY: callers hold the memory's host lock (or own it exclusively), so it is not mapped
    // elsewhere; the memory is HOST_VISIBLE | HOST_COHERENT, so no flush is needed.
    unsafe {
        let ptr = device
            .map_memory(memory, 0, len, vk::MemoryMapFlags::empty())
            .map_err(vk_err("vkMapMemory"))?;
        // `len` fits in usize: the bytes were a host slice, or a buffer within the storage range.
        let result = f(ptr.cast::<u8>(), usize::try_from(len).unwrap_or(usize::MAX));
        device.unmap_memory(memory);
        Ok(result)
    }
}
