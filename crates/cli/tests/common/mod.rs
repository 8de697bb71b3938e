//! Helpers shared by the CLI's relighting tests: a sample's coverage mask, read with the exr
//! crate independently of the trainer's decoder, and what a relit PNG must look like.
#![allow(dead_code)]

use lightfarm_trainer::infer::in_inset;

/// (width, height, `mask.A`) of a sample EXR.
pub fn sample_mask(bytes: &[u8]) -> (u32, u32, Vec<f32>) {
    use exr::prelude::{ReadChannels, ReadLayers};
    let img = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .expect("a readable sample EXR");
    let layer = &img.layer_data;
    let mask = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "mask.A")
        .expect("a mask.A channel")
        .sample_data
        .values_as_f32()
        .collect();
    (layer.size.width() as u32, layer.size.height() as u32, mask)
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
