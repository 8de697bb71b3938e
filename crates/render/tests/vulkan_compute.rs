//! The Vulkan layer end to end: a naga-compiled kernel over a million elements, buffer round
//! trips, and the errors users see for bad requests. Runs on whatever `auto` picks (lavapipe in
//! CI); a machine without any Vulkan device fails these tests rather than skipping them.

use std::str::FromStr;
use std::sync::Arc;

use lightfarm_render::vulkan::{
    list_devices, BindingKind, ComputeKernel, DeviceRequest, GpuBuffer, GpuContext, GpuImage,
    Resource, VulkanError,
};

/// naga 30 spells the push-constant address space `immediate` (formerly `push_constant`).
const DOUBLE_ADD: &str = r#"
struct Pc { add: u32, n: u32 }
var<immediate> pc: Pc;

@group(0) @binding(0) var<storage, read> a: array<u32>;
@group(0) @binding(1) var<storage, read_write> out: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i < pc.n) {
        out[i] = a[i] * 2u + pc.add;
    }
}
"#;

const WORKGROUP: u32 = 64;

fn compile(src: &str) -> Vec<u32> {
    let module = naga::front::wgsl::parse_str(src).expect("test shader parses");
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .expect("test shader validates");
    let opts = naga::back::spv::Options {
        lang_version: (1, 3),
        ..Default::default()
    };
    naga::back::spv::write_vec(
        &module,
        &info,
        &opts,
        Some(&naga::back::spv::PipelineOptions {
            shader_stage: naga::ShaderStage::Compute,
            entry_point: "main".into(),
        }),
    )
    .expect("test shader compiles to SPIR-V")
}

fn context() -> Arc<GpuContext> {
    GpuContext::new(&DeviceRequest::Auto).expect("a Vulkan device (lavapipe at least) is available")
}

fn push(add: u32, n: u32) -> Vec<u8> {
    [add, n].iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn kernel_doubles_and_adds_push_constant_over_a_million_elements() {
    let ctx = context();
    let n: u32 = 1_000_003;
    let add: u32 = 0x9e37_79b9;
    // Large, varied values so wrapping arithmetic and every lane are exercised.
    let input: Vec<u32> = (0..n)
        .map(|i| i.wrapping_mul(2_654_435_761) ^ 0x5bd1)
        .collect();
    let a = GpuBuffer::from_slice(&ctx, "a", &input).unwrap();
    let out = GpuBuffer::zeroed(&ctx, "out", u64::from(n) * 4).unwrap();
    let kernel = ComputeKernel::new(&ctx, "double_add", &compile(DOUBLE_ADD), 2, 8).unwrap();

    kernel
        .dispatch(&[&a, &out], &push(add, n), [n.div_ceil(WORKGROUP), 1, 1])
        .unwrap();

    let got: Vec<u32> = out.read().unwrap();
    assert_eq!(got.len(), n as usize);
    let first_bad = input
        .iter()
        .zip(&got)
        .position(|(x, y)| x.wrapping_mul(2).wrapping_add(add) != *y);
    assert_eq!(first_bad, None, "device result differs from the CPU");

    // A second dispatch with other constants over the same buffers proves the push constants
    // and the ordering between submissions, not a stale first result.
    kernel
        .dispatch(&[&a, &out], &push(7, n), [n.div_ceil(WORKGROUP), 1, 1])
        .unwrap();
    let got: Vec<u32> = out.read().unwrap();
    assert_eq!(
        got[n as usize - 1],
        input[n as usize - 1].wrapping_mul(2).wrapping_add(7)
    );
    assert!(input
        .iter()
        .zip(&got)
        .all(|(x, y)| x.wrapping_mul(2).wrapping_add(7) == *y));
}

#[test]
fn buffers_round_trip_and_empty_buffers_are_sixteen_zero_bytes() {
    let ctx = context();
    let data: Vec<f32> = (0..1000).map(|i| i as f32 * 0.25 - 3.0).collect();
    let buf = GpuBuffer::from_slice(&ctx, "floats", &data).unwrap();
    assert_eq!(buf.size(), 4000);
    assert_eq!(buf.read::<f32>().unwrap(), data);

    buf.write(&[1.5f32, 2.5]).unwrap();
    let back = buf.read::<f32>().unwrap();
    assert_eq!(&back[..2], &[1.5, 2.5]);
    assert_eq!(&back[2..], &data[2..]);

    let too_much = vec![0f32; 1001];
    assert!(matches!(
        buf.write(&too_much),
        Err(VulkanError::WriteTooLarge { capacity: 4000, .. })
    ));

    let empty = GpuBuffer::from_slice::<u32>(&ctx, "empty", &[]).unwrap();
    assert_eq!(empty.size(), 16);
    assert_eq!(empty.read::<u32>().unwrap(), vec![0; 4]);

    // Odd sizes: the tail element that does not fit is dropped, the bytes survive.
    let odd = GpuBuffer::from_slice(&ctx, "odd", &[1u8, 2, 3, 4, 5, 6, 7]).unwrap();
    assert_eq!(odd.size(), 7);
    assert_eq!(odd.read::<u8>().unwrap(), vec![1, 2, 3, 4, 5, 6, 7]);
    assert_eq!(
        odd.read::<u32>().unwrap(),
        vec![u32::from_le_bytes([1, 2, 3, 4])]
    );

    let zeros = GpuBuffer::zeroed(&ctx, "zeros", 40).unwrap();
    assert_eq!(zeros.read::<u64>().unwrap(), vec![0; 5]);
}

/// Copies record `pc.add + i` of a record image (rows of 4096 texels) to out[i].
const READ_RECORDS: &str = r#"
struct Pc { first: u32, n: u32 }
var<immediate> pc: Pc;

@group(0) @binding(0) var records: texture_storage_2d<rgba32uint, read>;
@group(0) @binding(1) var<storage, read_write> out: array<vec4<u32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i < pc.n) {
        let r = pc.first + i;
        out[i] = textureLoad(records, vec2<i32>(i32(r & 4095u), i32(r >> 12u)));
    }
}
"#;

#[test]
fn record_images_read_back_every_record_across_rows() {
    let ctx = context();
    // Three rows, the last one partial; records differ in every word.
    let n = 2 * 4096 + 1234u32;
    let records: Vec<[u32; 4]> = (0..n)
        .map(|i| [i, i ^ 0xdead_beef, i.wrapping_mul(2_654_435_761), !i])
        .collect();
    let image = GpuImage::from_records(&ctx, "records", &records).unwrap();
    assert_eq!(image.records(), u64::from(n));
    let kinds = [BindingKind::Image, BindingKind::StorageBuffer];
    let kernel =
        ComputeKernel::with_bindings(&ctx, "read_records", &compile(READ_RECORDS), &kinds, 8)
            .unwrap();
    // Scattered reads, so the lanes of each vector fetch from different rows.
    let first = 4000u32;
    let count = n - first;
    let out = GpuBuffer::zeroed(&ctx, "out", u64::from(count) * 16).unwrap();
    kernel
        .dispatch_resources(
            &[Resource::Image(&image), Resource::Buffer(&out)],
            &push(first, count),
            [count.div_ceil(WORKGROUP), 1, 1],
        )
        .unwrap();
    let got: Vec<[u32; 4]> = out.read().unwrap();
    assert_eq!(got, records[first as usize..]);

    // A buffer where the kernel wants an image is refused, naming the binding and buffer.
    let err = kernel
        .dispatch_resources(
            &[Resource::Buffer(&out), Resource::Buffer(&out)],
            &push(0, 1),
            [1, 1, 1],
        )
        .unwrap_err();
    assert!(
        matches!(err, VulkanError::BindingKindMismatch { binding: 0, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("`out`"), "{err}");
    // So is a kernel of images dispatched as plain buffers.
    let err = kernel
        .dispatch(&[&out, &out], &push(0, 1), [1, 1, 1])
        .unwrap_err();
    assert!(
        matches!(err, VulkanError::BindingKindMismatch { .. }),
        "{err}"
    );
}

#[test]
fn dispatch_with_the_wrong_number_of_buffers_is_an_error() {
    let ctx = context();
    let kernel = ComputeKernel::new(&ctx, "double_add", &compile(DOUBLE_ADD), 2, 8).unwrap();
    let a = GpuBuffer::zeroed(&ctx, "a", 64).unwrap();

    let err = kernel.dispatch(&[&a], &push(0, 16), [1, 1, 1]).unwrap_err();
    assert!(
        matches!(
            err,
            VulkanError::BindingCountMismatch {
                expected: 2,
                got: 1,
                ..
            }
        ),
        "{err}"
    );
    let err = kernel
        .dispatch(&[&a, &a, &a], &push(0, 16), [1, 1, 1])
        .unwrap_err();
    assert!(
        matches!(err, VulkanError::BindingCountMismatch { got: 3, .. }),
        "{err}"
    );

    let err = kernel
        .dispatch(&[&a, &a], &[0u8; 4], [1, 1, 1])
        .unwrap_err();
    assert!(
        matches!(
            err,
            VulkanError::PushConstantSizeMismatch {
                expected: 8,
                got: 4,
                ..
            }
        ),
        "{err}"
    );

    let too_many = [u32::MAX, 1, 1];
    let err = kernel
        .dispatch(&[&a, &a], &push(0, 16), too_many)
        .unwrap_err();
    assert!(matches!(err, VulkanError::DispatchTooLarge { .. }), "{err}");

    let err = ComputeKernel::new(&ctx, "bad", &compile(DOUBLE_ADD), 2, 100_000)
        .err()
        .expect("push constants beyond the device limit are refused");
    assert!(
        matches!(err, VulkanError::PushConstantsTooLarge { .. }),
        "{err}"
    );
}

#[test]
fn buffers_above_the_storage_range_are_refused_before_allocating() {
    let ctx = context();
    let limit = ctx.max_storage_buffer_range();
    assert!(
        limit >= 1 << 20,
        "implausible maxStorageBufferRange {limit}"
    );
    // Far beyond any device's memory: only the up-front check can answer this quickly.
    let err = GpuBuffer::zeroed(&ctx, "huge", limit + 1).unwrap_err();
    match &err {
        VulkanError::BufferTooLarge {
            label,
            bytes,
            limit: l,
        } => {
            assert_eq!(label, "huge");
            assert_eq!(*bytes, limit + 1);
            assert_eq!(*l, limit);
        }
        other => panic!("expected BufferTooLarge, got {other}"),
    }
    assert!(err.to_string().contains("maxStorageBufferRange"), "{err}");

    // Exactly at the limit is allowed (lavapipe's 128 MiB is affordable here).
    if ctx.is_cpu() {
        let at_limit = GpuBuffer::zeroed(&ctx, "at-limit", limit).unwrap();
        assert_eq!(at_limit.size(), limit);
    }
}

#[test]
fn device_requests_parse() {
    let parse = |s: &str| DeviceRequest::from_str(s).unwrap();
    assert_eq!(parse("auto"), DeviceRequest::Auto);
    assert_eq!(parse(""), DeviceRequest::Auto);
    assert_eq!(parse("  AUTO "), DeviceRequest::Auto);
    assert_eq!(parse("gpu"), DeviceRequest::Gpu);
    assert_eq!(parse("GPU"), DeviceRequest::Gpu);
    assert_eq!(parse("cpu"), DeviceRequest::Cpu);
    assert_eq!(parse("lavapipe"), DeviceRequest::Cpu);
    assert_eq!(parse("llvmpipe"), DeviceRequest::Cpu);
    assert_eq!(parse("0"), DeviceRequest::Index(0));
    assert_eq!(parse("12"), DeviceRequest::Index(12));
    assert_eq!(parse("-1"), DeviceRequest::Name("-1".into()));
    assert_eq!(parse("RTX 4090"), DeviceRequest::Name("RTX 4090".into()));
    assert_eq!(parse("nvidia"), DeviceRequest::Name("nvidia".into()));
}

#[test]
fn unknown_device_names_list_the_available_devices() {
    let devices = list_devices().unwrap();
    assert!(!devices.is_empty());
    for (i, d) in devices.iter().enumerate() {
        assert_eq!(d.index, i);
        assert!(
            [
                "discrete-gpu",
                "integrated-gpu",
                "virtual-gpu",
                "cpu",
                "other"
            ]
            .contains(&d.kind.as_str()),
            "{d:?}"
        );
    }
    // Listing twice gives the same order: indices are stable.
    let again: Vec<String> = list_devices()
        .unwrap()
        .into_iter()
        .map(|d| d.name)
        .collect();
    assert_eq!(
        again,
        devices.iter().map(|d| d.name.clone()).collect::<Vec<_>>()
    );

    let err = GpuContext::new(&DeviceRequest::Name("no-such-device".into()))
        .err()
        .expect("no device is called no-such-device");
    match &err {
        VulkanError::DeviceNotFound { request, available } => {
            assert_eq!(request, "no-such-device");
            for d in &devices {
                assert!(available.contains(&d.name), "{available} lacks {}", d.name);
            }
        }
        other => panic!("expected DeviceNotFound, got {other}"),
    }

    let err = GpuContext::new(&DeviceRequest::Index(devices.len()))
        .err()
        .expect("index past the end");
    assert!(matches!(err, VulkanError::DeviceNotFound { .. }), "{err}");

    // A name match is case-insensitive and picks that very device.
    let first = &devices[0];
    let ctx = GpuContext::new(&DeviceRequest::Name(first.name.to_uppercase())).unwrap();
    assert_eq!(ctx.info().name, first.name);
    let by_index = GpuContext::new(&DeviceRequest::Index(0)).unwrap();
    assert_eq!(by_index.info().name, first.name);
    if devices.iter().any(|d| d.kind == "cpu") {
        assert!(GpuContext::new(&DeviceRequest::Cpu).unwrap().is_cpu());
    }
}

#[test]
fn gpu_context_is_shareable_across_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<GpuContext>();
    assert_send_sync::<GpuBuffer>();
    assert_send_sync::<ComputeKernel>();

    let ctx = context();
    let kernel =
        Arc::new(ComputeKernel::new(&ctx, "double_add", &compile(DOUBLE_ADD), 2, 8).unwrap());
    let handles: Vec<_> = (0..3u32)
        .map(|t| {
            let (ctx, kernel) = (Arc::clone(&ctx), Arc::clone(&kernel));
            std::thread::spawn(move || {
                let input: Vec<u32> = (0..1000).map(|i| i + t * 1000).collect();
                let a = GpuBuffer::from_slice(&ctx, "a", &input).unwrap();
                let out = GpuBuffer::zeroed(&ctx, "out", 4000).unwrap();
                kernel
                    .dispatch(&[&a, &out], &push(t, 1000), [16, 1, 1])
                    .unwrap();
                let got: Vec<u32> = out.read().unwrap();
                assert!(input.iter().zip(&got).all(|(x, y)| x * 2 + t == *y));
            })
        })
        .collect();
    for h in handles {
        h.join().unwrap();
    }
}
