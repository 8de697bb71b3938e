//! The Vulkan layer: device choice, storage buffers, record images and compute kernels.
//!
//! This is the only module of the project that touches `ash`; everything above it speaks in
//! [`GpuContext`], [`GpuBuffer`] and [`ComputeKernel`]. Every submission is synchronous (it waits
//! on a fence), which keeps ownership simple: when a call returns, the GPU is done with every
//! buffer it was given.

mod buffer;
mod context;
mod image;
mod kernel;

use std::convert::Infallible;
use std::fmt;
use std::str::FromStr;

pub use buffer::GpuBuffer;
pub use context::{list_devices, GpuContext, FORCE_STAGING_ENV};
pub use image::{GpuImage, RECORDS_PER_ROW};
pub use kernel::{BindingKind, ComputeKernel, Resource};

/// The one hint shared by every "no Vulkan here" error, so users see the same fix everywhere.
const INSTALL_HINT: &str =
    "install the Vulkan loader and the CPU driver: `apt-get install libvulkan1 mesa-vulkan-drivers`";

/// Everything that can go wrong in the Vulkan layer; every message ends with what to do.
#[derive(Debug, thiserror::Error)]
pub enum VulkanError {
    #[error("the Vulkan loader (libvulkan.so.1) could not be loaded ({detail}); {INSTALL_HINT}")]
    LoaderMissing { detail: String },

    #[error(
        "no Vulkan device with compute support (Vulkan 1.1 or newer) was found; {INSTALL_HINT}"
    )]
    NoDevice,

    #[error(
        "no Vulkan device matches the request `{request}`; available devices: {available}. \
         Pick one by index or by part of its name, or use `auto`"
    )]
    DeviceNotFound { request: String, available: String },

    #[error(
        "Vulkan call {what} failed with {code}; update the GPU driver or select another device \
         (set VK_INSTANCE_LAYERS=VK_LAYER_KHRONOS_validation to see details)"
    )]
    Vk {
        what: &'static str,
        code: ash::vk::Result,
    },

    #[error(
        "`{label}` holds {records} records but an image on this device holds at most {limit} \
         (maxImageDimension2D rows of 4096); render a smaller scene or use another device"
    )]
    ImageTooLarge {
        label: String,
        records: u64,
        limit: u64,
    },

    #[error(
        "buffer `{label}` needs {bytes} bytes but the device's maxStorageBufferRange is {limit} \
         bytes; split the data into several buffers or use a device with a larger limit"
    )]
    BufferTooLarge {
        label: String,
        bytes: u64,
        limit: u64,
    },

    #[error(
        "out of memory allocating {bytes} bytes for buffer `{label}` ({code}); reduce the scene \
         or image size, close other GPU programs, or select a device with more memory"
    )]
    OutOfMemory {
        label: String,
        bytes: u64,
        code: ash::vk::Result,
    },

    #[error(
        "the device offers no memory type usable for buffer `{label}`; this is a driver problem: \
         update the driver or select another device"
    )]
    NoMemoryType { label: String },

    #[error(
        "writing {bytes} bytes into buffer `{label}` of {capacity} bytes; create a larger buffer \
         or write less data"
    )]
    WriteTooLarge {
        label: String,
        bytes: u64,
        capacity: u64,
    },

    #[error(
        "kernel `{kernel}` declares {expected} bindings but was dispatched with {got} buffers; \
         pass exactly one buffer per binding"
    )]
    BindingCountMismatch {
        kernel: String,
        expected: u32,
        got: usize,
    },

    #[error(
        "kernel `{kernel}` wants a {expected} at binding {binding} but was given `{got}`; bind \
         resources in the order and kinds the shader declares"
    )]
    BindingKindMismatch {
        kernel: String,
        binding: u32,
        expected: String,
        got: String,
    },

    #[error(
        "kernel `{kernel}` declares {expected} bytes of push constants but was given {got}; \
         pass a block of exactly the declared size"
    )]
    PushConstantSizeMismatch {
        kernel: String,
        expected: u32,
        got: usize,
    },

    #[error(
        "kernel `{kernel}` wants {bytes} bytes of push constants; they must be a multiple of 4 \
         and at most the device's maxPushConstantsSize of {limit}: move data into a buffer"
    )]
    PushConstantsTooLarge {
        kernel: String,
        bytes: u32,
        limit: u32,
    },

    #[error(
        "kernel `{kernel}` dispatch of {groups:?} workgroups exceeds the device's \
         maxComputeWorkGroupCount {limit:?}; dispatch in several smaller batches"
    )]
    DispatchTooLarge {
        kernel: String,
        groups: [u32; 3],
        limit: [u32; 3],
    },

    #[error(
        "buffer `{buffer}` was created on another GPU context than kernel `{kernel}`; create \
         buffers and kernels from the same GpuContext"
    )]
    ForeignBuffer { kernel: String, buffer: String },

    #[error("kernel `{kernel}` was given empty SPIR-V; check that the shader compiled")]
    EmptySpirv { kernel: String },
}

/// Which device to run on, as a user writes it (`--device gpu`, `--device 1`, `--device rtx`).
#[derive(Clone, Debug, PartialEq)]
pub enum DeviceRequest {
    /// The best device: discrete GPU, else integrated, else virtual, else the CPU.
    Auto,
    /// Any GPU, preferring discrete ones; an error on CPU-only machines.
    Gpu,
    /// The CPU implementation (Mesa lavapipe).
    Cpu,
    /// The device at this index of [`list_devices`].
    Index(usize),
    /// The first device whose name contains this text, ignoring case.
    Name(String),
}

impl FromStr for DeviceRequest {
    /// Every string names something (at worst a device name that matches nothing, which is
    /// reported when the context is created, together with the list of devices).
    type Err = Infallible;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let trimmed = s.trim();
        let lower = trimmed.to_ascii_lowercase();
        Ok(match lower.as_str() {
            "" | "auto" => DeviceRequest::Auto,
            "gpu" => DeviceRequest::Gpu,
            "cpu" | "lavapipe" | "llvmpipe" => DeviceRequest::Cpu,
            _ => match trimmed.parse::<usize>() {
                Ok(index) => DeviceRequest::Index(index),
                Err(_) => DeviceRequest::Name(trimmed.to_string()),
            },
        })
    }
}

impl fmt::Display for DeviceRequest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceRequest::Auto => f.write_str("auto"),
            DeviceRequest::Gpu => f.write_str("gpu"),
            DeviceRequest::Cpu => f.write_str("cpu"),
            DeviceRequest::Index(index) => write!(f, "{index}"),
            DeviceRequest::Name(name) => f.write_str(name),
        }
    }
}

/// A device as reported to users (`lightfarm devices`) and recorded in render metadata.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DeviceInfo {
    /// Position in the deterministic order of [`list_devices`]; what `DeviceRequest::Index` means.
    pub index: usize,
    pub name: String,
    /// "discrete-gpu", "integrated-gpu", "virtual-gpu", "cpu" or "other".
    pub kind: String,
    pub driver: String,
    pub api_version: String,
}

impl DeviceInfo {
    /// Whether this is a GPU of any kind, as `DeviceRequest::Gpu` understands it.
    pub fn is_gpu(&self) -> bool {
        matches!(
            self.kind.as_str(),
            "discrete-gpu" | "integrated-gpu" | "virtual-gpu"
        )
    }
}

/// Maps a failed Vulkan call to an error that names the call; allocation failures get their own
/// variant at the call sites that know the buffer, everything else lands here.
pub(crate) fn vk_err(what: &'static str) -> impl Fn(ash::vk::Result) -> VulkanError {
    move |code| VulkanError::Vk { what, code }
}
