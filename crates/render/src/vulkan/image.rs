//! Read-only tables of 16-byte records held in a 2D image (R32G32B32A32_UINT) instead of a
//! storage buffer, for the records a kernel reads most at scattered addresses (BVH nodes).
//!
//! Why an image: lavapipe compiles a storage-buffer load whose address differs between the
//! lanes of a SIMD vector into one bounds-checked scalar load per lane and component, with a
//! branch for each (Mesa 25 `emit_load_mem`), while a texel fetch is a vector gather with
//! vector bounds checks. GPUs read either well. Record `i` is texel `(i % ROW, i / ROW)`.

use std::sync::Arc;

use ash::vk;

use super::buffer::{memory_type, GpuBuffer};
use super::{vk_err, GpuContext, VulkanError};

/// Texels per image row: a power of two (the shader splits an index with a mask and a shift)
/// that every Vulkan device supports as a width (maxImageDimension2D ≥ 4096).
pub const RECORDS_PER_ROW: u32 = 4096;

const FORMAT: vk::Format = vk::Format::R32G32B32A32_UINT;

/// A read-only storage image of 16-byte records, bound with [`super::Resource::Image`].
pub struct GpuImage {
    ctx: Arc<GpuContext>,
    label: String,
    image: vk::Image,
    view: vk::ImageView,
    memory: vk::DeviceMemory,
    records: u64,
}

impl GpuImage {
    /// An image holding `records` (one texel each; the last row is padded with zeros). No
    /// records still make a 1×1 image, as a binding needs something to point at.
    pub fn from_records(
        ctx: &Arc<GpuContext>,
        label: &str,
        records: &[[u32; 4]],
    ) -> Result<GpuImage, VulkanError> {
        let n = records.len() as u64;
        let (width, height) = extent(n, ctx.limits().max_image_dimension2_d).ok_or_else(|| {
            VulkanError::ImageTooLarge {
                label: label.to_string(),
                records: n,
                limit: u64::from(ctx.limits().max_image_dimension2_d) * u64::from(RECORDS_PER_ROW),
            }
        })?;
        let device = ctx.device();
        let mut img = GpuImage {
            ctx: Arc::clone(ctx),
            label: label.to_string(),
            image: vk::Image::null(),
            view: vk::ImageView::null(),
            memory: vk::DeviceMemory::null(),
            records: n,
        };
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(FORMAT)
            .extent(vk::Extent3D {
                width,
                height,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_DST)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        let whole = vk::ImageSubresourceRange::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .level_count(1)
            .layer_count(1);
        // SAFETY: the create infos only borrow locals; `img` owns each handle as soon as it
        // exists, so its Drop frees them on every early return.
        unsafe {
            img.image = device
                .create_image(&info, None)
                .map_err(vk_err("vkCreateImage"))?;
            let needs = device.get_image_memory_requirements(img.image);
            let Some((type_index, _)) = memory_type(
                ctx.memory_properties(),
                needs.memory_type_bits,
                vk::MemoryPropertyFlags::empty(),
                vk::MemoryPropertyFlags::DEVICE_LOCAL,
            ) else {
                return Err(VulkanError::NoMemoryType {
                    label: label.to_string(),
                });
            };
            img.memory = device
                .allocate_memory(
                    &vk::MemoryAllocateInfo::default()
                        .allocation_size(needs.size)
                        .memory_type_index(type_index),
                    None,
                )
                .map_err(|code| VulkanError::OutOfMemory {
                    label: label.to_string(),
                    bytes: needs.size,
                    code,
                })?;
            device
                .bind_image_memory(img.image, img.memory, 0)
                .map_err(vk_err("vkBindImageMemory"))?;
            img.view = device
                .create_image_view(
                    &vk::ImageViewCreateInfo::default()
                        .image(img.image)
                        .view_type(vk::ImageViewType::TYPE_2D)
                        .format(FORMAT)
                        .subresource_range(whole),
                    None,
                )
                .map_err(vk_err("vkCreateImageView"))?;
        }
        // The records go up through a buffer, padded to whole rows, then are copied in.
        let mut padded = records.to_vec();
        padded.resize(width as usize * height as usize, [0; 4]);
        let staging = GpuBuffer::from_slice(ctx, &format!("{label} (upload)"), &padded)?;
        let (src, dst_image) = (staging.raw(), img.image);
        ctx.submit_and_wait("vkCmdCopyBufferToImage", |device, cmd| {
            let layout = |old, new, before, after| {
                vk::ImageMemoryBarrier::default()
                    .old_layout(old)
                    .new_layout(new)
                    .src_access_mask(before)
                    .dst_access_mask(after)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .image(dst_image)
                    .subresource_range(whole)
            };
            let to_transfer = layout(
                vk::ImageLayout::UNDEFINED,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                vk::AccessFlags::empty(),
                vk::AccessFlags::TRANSFER_WRITE,
            );
            let to_shader = layout(
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                vk::ImageLayout::GENERAL,
                vk::AccessFlags::TRANSFER_WRITE,
                vk::AccessFlags::SHADER_READ,
            );
            let region = vk::BufferImageCopy::default()
                .image_subresource(
                    vk::ImageSubresourceLayers::default()
                        .aspect_mask(vk::ImageAspectFlags::COLOR)
                        .layer_count(1),
                )
                .image_extent(vk::Extent3D {
                    width,
                    height,
                    depth: 1,
                });
            // SAFETY: `cmd` is recording; the staging buffer holds width × height texels.
            unsafe {
                device.cmd_pipeline_barrier(
                    cmd,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[to_transfer],
                );
                device.cmd_copy_buffer_to_image(
                    cmd,
                    src,
                    dst_image,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    &[region],
                );
                device.cmd_pipeline_barrier(
                    cmd,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::COMPUTE_SHADER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[to_shader],
                );
            }
        })?;
        tracing::debug!(label, records = n, width, height, "uploaded record image");
        Ok(img)
    }

    /// Number of records as given (the image may hold padding after them).
    pub fn records(&self) -> u64 {
        self.records
    }

    pub fn label(&self) -> &str {
        &self.label
    }

    pub(crate) fn view(&self) -> vk::ImageView {
        self.view
    }

    pub(crate) fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }
}

/// Width and height of an image of `records` texels, rows of [`RECORDS_PER_ROW`] (fewer when
/// all fit in one row; at least 1×1); None when it needs more than `max_dim` rows.
fn extent(records: u64, max_dim: u32) -> Option<(u32, u32)> {
    let width = u64::from(RECORDS_PER_ROW).min(records.max(1));
    let height = records.div_ceil(u64::from(RECORDS_PER_ROW)).max(1);
    (height <= u64::from(max_dim)).then_some((width as u32, height as u32))
}

impl Drop for GpuImage {
    fn drop(&mut self) {
        // SAFETY: submissions are synchronous, so the device no longer uses the image; null
        // handles (a failed creation) are ignored.
        unsafe {
            let device = self.ctx.device();
            device.destroy_image_view(self.view, None);
            device.destroy_image(self.image, None);
            device.free_memory(self.memory, None);
        }
    }
}

impl std::fmt::Debug for GpuImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuImage")
            .field("label", &self.label)
            .field("records", &self.records)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_fill_rows_of_4096_and_the_row_limit_is_kept() {
        assert_eq!(extent(0, 16384), Some((1, 1)));
        assert_eq!(extent(5, 16384), Some((5, 1)));
        assert_eq!(extent(4096, 16384), Some((4096, 1)));
        assert_eq!(extent(4097, 16384), Some((4096, 2)));
        assert_eq!(extent(4096 * 16384, 16384), Some((4096, 16384)));
        assert_eq!(extent(4096 * 16384 + 1, 16384), None);
    }
}
