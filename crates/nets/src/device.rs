//! Which Burn device the networks run on.

use burn::prelude::*;

use crate::NetsError;

/// `cpu` (Burn's pure-Rust flex backend), `gpu` (wgpu; needs the `gpu` feature) or `auto`
/// (gpu when compiled in, else cpu). Training wraps the result in `.autodiff()`.
pub fn select(name: &str) -> Result<Device, NetsError> {
    match name.trim().to_ascii_lowercase().as_str() {
        "cpu" | "flex" => Ok(Device::flex()),
        "gpu" | "wgpu" => gpu(),
        "auto" | "" => {
            if cfg!(feature = "gpu") {
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

#[cfg(feature = "gpu")]
fn gpu() -> Result<Device, NetsError> {
    Ok(Device::wgpu(DeviceKind::DefaultDevice))
}

#[cfg(not(feature = "gpu"))]
fn gpu() -> Result<Device, NetsError> {
    Err(NetsError::Device(
        "this build has no GPU backend: rebuild with `cargo build --release --features gpu` \
         (Burn's wgpu backend), or train with --device cpu"
            .into(),
    ))
}
