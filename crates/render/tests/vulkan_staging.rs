//! The staging-buffer path discrete GPUs take (device memory the host cannot map), forced on
//! through `LIGHTFARM_VULKAN_FORCE_STAGING` so that lavapipe, whose memory is all mappable,
//! exercises it in CI. One test function: the variable is process-wide and must be set before
//! any context exists.

use std::sync::Arc;

use lightfarm_render::vulkan::{
    ComputeKernel, DeviceRequest, GpuBuffer, GpuContext, VulkanError, FORCE_STAGING_ENV,
};

const SCALE_ADD: &str = r#"
struct Pc { add: u32, n: u32 }
var<immediate> pc: Pc;

@group(0) @binding(0) var<storage, read_write> data: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i < pc.n) {
        data[i] = data[i] * 3u + pc.add;
    }
}
"#;

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

fn staged_context() -> Arc<GpuContext> {
    std::env::set_var(FORCE_STAGING_ENV, "1");
    GpuContext::new(&DeviceRequest::Auto).expect("a Vulkan device (lavapipe at least) is available")
}

#[test]
fn staging_path_uploads_fills_dispatches_and_reads_back() {
    let ctx = staged_context();

    // Upload + readback, including a size that is not a multiple of 4.
    let odd = GpuBuffer::from_slice(&ctx, "odd", &[9u8, 8, 7, 6, 5]).unwrap();
    assert_eq!(odd.size(), 5);
    // The knob took effect: no buffer is read or written by mapping.
    assert!(format!("{odd:?}").contains("mappable: false"), "{odd:?}");
    assert_eq!(odd.read::<u8>().unwrap(), vec![9, 8, 7, 6, 5]);

    // Zero fill through vkCmdFillBuffer, after the memory held something else.
    let junk = GpuBuffer::from_slice(&ctx, "junk", &vec![0xffff_ffffu32; 4096]).unwrap();
    drop(junk);
    let zeros = GpuBuffer::zeroed(&ctx, "zeros", 4 * 4096 + 3).unwrap();
    assert!(zeros.read::<u8>().unwrap().iter().all(|b| *b == 0));
    assert_eq!(zeros.read::<u8>().unwrap().len(), 4 * 4096 + 3);

    let empty = GpuBuffer::from_slice::<u64>(&ctx, "empty", &[]).unwrap();
    assert_eq!(empty.read::<u64>().unwrap(), vec![0, 0]);

    // Partial overwrite keeps the rest.
    let n: u32 = 100_003;
    let input: Vec<u32> = (0..n).map(|i| i.wrapping_mul(0x2545_f491)).collect();
    let data = GpuBuffer::from_slice(&ctx, "data", &input).unwrap();
    data.write(&[5u32, 6, 7]).unwrap();
    let mut expected = input.clone();
    expected[..3].copy_from_slice(&[5, 6, 7]);
    assert_eq!(data.read::<u32>().unwrap(), expected);

    // An in-place kernel: the upload must be visible to the shader and its writes to the copy.
    let kernel = ComputeKernel::new(&ctx, "scale_add", &compile(SCALE_ADD), 1, 8).unwrap();
    let push: Vec<u8> = [11u32, n].iter().flat_map(|v| v.to_le_bytes()).collect();
    kernel
        .dispatch(&[&data], &push, [n.div_ceil(64), 1, 1])
        .unwrap();
    let got = data.read::<u32>().unwrap();
    let first_bad = expected
        .iter()
        .zip(&got)
        .position(|(x, y)| x.wrapping_mul(3).wrapping_add(11) != *y);
    assert_eq!(first_bad, None);

    // Limits still apply before anything is allocated.
    let limit = ctx.max_storage_buffer_range();
    assert!(matches!(
        GpuBuffer::zeroed(&ctx, "huge", limit + 1),
        Err(VulkanError::BufferTooLarge { .. })
    ));
    assert!(matches!(
        data.write(&vec![0u32; n as usize + 1]),
        Err(VulkanError::WriteTooLarge { .. })
    ));
}
