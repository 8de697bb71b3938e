//! Which Burn device the networks run on.

use burn::prelude::*;

use crate::NetsError;

/// `cpu` (Burn's pure-Rust flex backend), `gpu` (wgpu, or Vulkan with Burn's SPIR-V compiler
/// under `gpu-vulkan`; needs the `gpu` feature and a hardware GPU) or `auto`
/// (gpu when compiled in and a hardware GPU is present, else cpu: on a CPU-only machine wgpu
/// would fall back to lavapipe, several times slower than flex). Training wraps the result in
/// `.autodiff()`.
pub fn select(name: &str) -> Result<Device, NetsError> {
    match name.trim().to_ascii_lowercase().as_str() {
        "cpu" | "flex" => Ok(Device::flex()),
        "gpu" | "wgpu" => gpu(),
        "auto" | "" => {
            if hardware_gpu() {
                gpu()
            } else {
                Ok(Device::flex())
            }
        }
        other => Err(NetsError::Device(format!(
            "unknown training device '{other}': use cpu, gpu or auto"
        ))),
    }
}

/// The wgpu device, on a hardware GPU only: asked for `gpu` on a machine whose only adapter is
/// lavapipe, wgpu would hand Burn's kernels to it (slower than flex, and Burn's SPIR-V kernels
/// crash it), so that is refused.
#[cfg(feature = "gpu")]
fn gpu() -> Result<Device, NetsError> {
    if !hardware_gpu() {
        return Err(NetsError::Device(
            "training device 'gpu': wgpu finds no hardware GPU here (a CPU Vulkan driver such as \
             lavapipe does not count); train with --device cpu, or check the GPU driver with \
             `vulkaninfo --summary`"
                .into(),
        ));
    }
    // `gpu-vulkan` pins Vulkan, so the SPIR-V compiler (tensor cores) does the kernels.
    #[cfg(feature = "gpu-vulkan")]
    return Ok(Device::vulkan(DeviceKind::DefaultDevice));
    #[cfg(not(feature = "gpu-vulkan"))]
    Ok(Device::wgpu(DeviceKind::DefaultDevice))
}

/// Whether wgpu sees a discrete, integrated or virtual GPU (not a software rasteriser).
#[cfg(feature = "gpu")]
pub fn hardware_gpu() -> bool {
    use std::future::Future;
    use std::task::{Context, Poll, Waker};
    let instance = wgpu::Instance::default();
    let adapters = std::pin::pin!(instance.enumerate_adapters(wgpu::Backends::all()));
    // Native enumeration is synchronous behind the future; one poll finishes it.
    match adapters.poll(&mut Context::from_waker(Waker::noop())) {
        Poll::Ready(list) => list.iter().any(|a| {
            matches!(
                a.get_info().device_type,
                wgpu::DeviceType::DiscreteGpu
                    | wgpu::DeviceType::IntegratedGpu
                    | wgpu::DeviceType::VirtualGpu
            )
        }),
        Poll::Pending => false,
    }
}

/// Whether wgpu sees a hardware GPU: never without the `gpu` feature.
#[cfg(not(feature = "gpu"))]
pub fn hardware_gpu() -> bool {
    false
}

#[cfg(not(feature = "gpu"))]
fn gpu() -> Result<Device, NetsError> {
    Err(NetsError::Device(
        "this build has no GPU backend: rebuild with `cargo build --release --features gpu` \
         (Burn's wgpu backend), or train with --device cpu"
            .into(),
    ))
}
