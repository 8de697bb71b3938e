//! Helpers shared by the CLI's tests: the repository, the binary, EXR channels and a sample's
//! coverage mask read with the exr crate independently of the trainer's decoder, and what a
//! relit PNG must look like.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use lightfarm_trainer::infer::in_inset;

/// The repository root.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The lines of a run directory's `losses.jsonl` (none when it does not exist yet).
pub fn losses(run: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(run.join("losses.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// Runs the `lightfarm` binary built for these tests.
pub fn lightfarm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lightfarm"))
        .args(args)
        .output()
        .expect("run lightfarm")
}

/// (width, height, the named channels) of an EXR's first layer, read with the exr crate.
pub fn exr_channels(bytes: &[u8], names: &[&str]) -> (u32, u32, Vec<Vec<f32>>) {
    use exr::prelude::{ReadChannels, ReadLayers};
    let img = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .expect("a readable EXR");
    let layer = &img.layer_data;
    let channels = names
        .iter()
        .map(|n| {
            layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.to_string() == *n)
                .unwrap_or_else(|| panic!("no channel {n}"))
                .sample_data
                .values_as_f32()
                .collect()
        })
        .collect();
    (
        layer.size.width() as u32,
        layer.size.height() as u32,
        channels,
    )
}

/// (width, height, `mask.A`) of a sample EXR.
pub fn sample_mask(bytes: &[u8]) -> (u32, u32, Vec<f32>) {
    let (w, h, mut c) = exr_channels(bytes, &["mask.A"]);
    (w, h, c.remove(0))
}

/// Whether (x, y) of a `w × h` relit image lies under the light-ball inset.
pub fn inset(w: u32, h: u32, x: u32, y: u32) -> bool {
    in_inset(w as usize, h as usize, x as usize, y as usize)
}

/// Pixel positions of a `w × h` image in row-major order.
pub fn positions(w: u32, h: u32) -> impl Iterator<Item = (u32, u32)> {
    (0..h).flat_map(move |y| (0..w).map(move |x| (x, y)))
}

/// A relit image is the network's output times the mask: black wherever `mask` is 0, outside
/// the inset, and not black everywhere on the subject.
pub fn assert_relit_masked(img: &image::RgbImage, mask: &[f32], what: &str) {
    let (w, h) = img.dimensions();
    assert_eq!(mask.len(), (w * h) as usize, "{what}: mask size");
    let mut subject_lit = false;
    for (x, y) in positions(w, h).filter(|&(x, y)| !inset(w, h, x, y)) {
        let p = img.get_pixel(x, y).0;
        if mask[(y * w + x) as usize] == 0.0 {
            assert_eq!(p, [0, 0, 0], "{what} at ({x}, {y}) is off the mask");
        } else {
            subject_lit |= p != [0, 0, 0];
        }
    }
    assert!(subject_lit, "{what}: the relit subject is black everywhere");
}
