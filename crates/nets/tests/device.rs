//! The training device is chosen at run time: Burn's flex backend on a machine without a
//! hardware GPU, the wgpu backend only on a hardware adapter. A CPU-only machine must never get
//! a wgpu device: wgpu would fall back to lavapipe, several times slower than flex, and Burn's
//! GPU kernels have crashed lavapipe before (reference/stack.md).
//!
//! The default build has no GPU backend; `cargo test -p lightfarm-nets --features gpu --test
//! device` runs the same tests with wgpu compiled in, where `auto` asks wgpu for its adapters
//! and must still answer flex when the only one is lavapipe (a CPU adapter).

use burn::prelude::*;
use lightfarm_nets::device::{hardware_gpu, select};

#[test]
fn cpu_and_its_spellings_are_flex() {
    for name in ["cpu", "CPU", " flex "] {
        assert_eq!(select(name).expect(name), Device::flex(), "{name:?}");
    }
}

#[test]
fn auto_on_a_machine_without_a_hardware_gpu_is_flex() {
    if hardware_gpu() {
        eprintln!("this machine has a hardware GPU: `auto` may take it, nothing to check here");
        return;
    }
    for name in ["auto", "", "Auto"] {
        assert_eq!(select(name).expect(name), Device::flex(), "{name:?}");
    }
}

#[cfg(not(feature = "gpu"))]
#[test]
fn a_build_without_the_gpu_backend_sees_no_gpu_and_says_how_to_get_one() {
    assert!(!hardware_gpu());
    let err = select("gpu")
        .expect_err("no GPU backend compiled in")
        .to_string();
    assert!(
        err.contains("--features gpu") && err.contains("--device cpu"),
        "{err}"
    );
}

/// With wgpu compiled in, a machine whose Vulkan driver is lavapipe (CI, CPU nodes) has only a
/// CPU adapter: it is not a hardware GPU.
#[cfg(feature = "gpu")]
#[test]
fn lavapipe_is_not_a_hardware_gpu() {
    let instance = wgpu::Instance::default();
    let adapters = pollster_block(instance.enumerate_adapters(wgpu::Backends::all()));
    let kinds: Vec<_> = adapters.iter().map(|a| a.get_info()).collect();
    let only_cpu = kinds.iter().all(|i| {
        i.device_type == wgpu::DeviceType::Cpu || i.device_type == wgpu::DeviceType::Other
    });
    if !only_cpu {
        eprintln!("hardware adapters present ({kinds:?}): nothing to check here");
        return;
    }
    assert!(!hardware_gpu(), "adapters {kinds:?}");
    assert_eq!(select("auto").expect("auto"), Device::flex());
    // Asked for by name, the GPU backend is refused rather than run on lavapipe.
    let err = select("gpu").expect_err("no hardware GPU").to_string();
    assert!(
        err.contains("no hardware GPU") && err.contains("--device cpu"),
        "{err}"
    );
}

#[cfg(feature = "gpu")]
fn pollster_block<F: std::future::Future>(f: F) -> F::Output {
    use std::task::{Context, Poll, Waker};
    let mut f = std::pin::pin!(f);
    loop {
        if let Poll::Ready(v) = f.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
            return v;
        }
        std::thread::yield_now();
    }
}

#[test]
fn an_unknown_device_is_named() {
    let err = select("tpu").expect_err("unknown").to_string();
    assert!(
        err.contains("'tpu'") && err.contains("cpu, gpu or auto"),
        "{err}"
    );
}
