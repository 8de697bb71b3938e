//! The labelled contact sheet of `lightfarm preview`: one row of tiles per sample.

use lightfarm_render::RenderOutput;

/// Column titles, in tile order.
pub const COLUMNS: [&str; 6] = ["lit0", "lit1", "albedo", "normal", "normal_lens", "mask"];

/// Height of a text line: the 8×8 glyphs plus a 2-pixel margin above and below.
const LINE_H: u32 = 12;
const GAP: u32 = 2;

fn srgb(x: f32) -> u8 {
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Tiles of one rendered sample, RGB8, `width × height` each, in [`COLUMNS`] order.
pub fn tiles(out: &RenderOutput) -> Vec<Vec<[u8; 3]>> {
    let mut tiles = Vec::with_capacity(COLUMNS.len());
    for lit in out.lit.iter().take(2) {
        // Exposure from the subject's mean luminance (as the single-render preview), so two
        // lightings of very different brightness both read.
        let (sum, weight) = lit
            .iter()
            .zip(&out.mask)
            .fold((0.0f64, 0.0f64), |(s, w), (p, m)| {
                let y = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
                (s + y as f64, w + *m as f64)
            });
        let exposure = if sum > 0.0 {
            (0.18 * weight / sum) as f32
        } else {
            1.0
        };
        tiles.push(
            lit.iter()
                .map(|p| {
                    p.map(|c| {
                        let e = c.max(0.0) * exposure;
                        srgb(e / (1.0 + e))
                    })
                })
                .collect(),
        );
    }
    tiles.push(out.albedo.iter().map(|p| p.map(srgb)).collect());
    for normals in [&out.normal, &out.normal_lens] {
        tiles.push(
            normals
                .iter()
                .map(|n| {
                    if n.iter().all(|c| *c == 0.0) {
                        [0, 0, 0]
                    } else {
                        n.map(|c| ((c * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0 + 0.5) as u8)
                    }
                })
                .collect(),
        );
    }
    tiles.push(
        out.mask
            .iter()
            .map(|m| [(m.clamp(0.0, 1.0) * 255.0 + 0.5) as u8; 3])
            .collect(),
    );
    tiles
}

/// An RGB canvas that text and tiles are drawn into.
pub struct Sheet {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<u8>,
    tile_w: u32,
    tile_h: u32,
}

impl Sheet {
    /// A sheet for `rows` samples of `tile_w × tile_h` tiles: a header line with the column
    /// titles, then per sample a caption line and a row of tiles.
    pub fn new(rows: u32, tile_w: u32, tile_h: u32) -> Sheet {
        let width = COLUMNS.len() as u32 * (tile_w + GAP) + GAP;
        let height = LINE_H + rows * (LINE_H + tile_h + GAP) + GAP;
        let mut sheet = Sheet {
            width,
            height,
            pixels: vec![24; (width * height * 3) as usize],
            tile_w,
            tile_h,
        };
        for (c, title) in COLUMNS.iter().enumerate() {
            let x = GAP + c as u32 * (tile_w + GAP);
            sheet.text(x + 2, 2, title, [255, 255, 255]);
        }
        sheet
    }

    /// Writes `text` with its top-left at (x, y); characters outside the canvas are clipped,
    /// characters without a glyph are drawn as `?`.
    pub fn text(&mut self, x: u32, y: u32, text: &str, colour: [u8; 3]) {
        use font8x8::UnicodeFonts;
        for (i, ch) in text.chars().enumerate() {
            let glyph = font8x8::BASIC_FONTS
                .get(ch)
                .or_else(|| font8x8::BASIC_FONTS.get('?'))
                .unwrap_or([0; 8]);
            let x0 = x + i as u32 * 8;
            for (gy, bits) in glyph.iter().enumerate() {
                for gx in 0..8 {
                    if bits & (1 << gx) != 0 {
                        self.put(x0 + gx, y + gy as u32, colour);
                    }
                }
            }
        }
    }

    fn put(&mut self, x: u32, y: u32, colour: [u8; 3]) {
        if x < self.width && y < self.height {
            let k = ((y * self.width + x) * 3) as usize;
            self.pixels[k..k + 3].copy_from_slice(&colour);
        }
    }

    /// Draws sample row `row`: its caption and its tiles (each `tile_w × tile_h`).
    pub fn row(&mut self, row: u32, caption: &str, tiles: &[Vec<[u8; 3]>]) {
        let y0 = LINE_H + row * (LINE_H + self.tile_h + GAP);
        self.text(GAP + 2, y0 + 2, caption, [255, 220, 120]);
        for (c, tile) in tiles.iter().enumerate() {
            let x0 = GAP + c as u32 * (self.tile_w + GAP);
            for (i, p) in tile.iter().enumerate() {
                let (x, y) = (i as u32 % self.tile_w, i as u32 / self.tile_w);
                self.put(x0 + x, y0 + LINE_H + y, *p);
            }
        }
    }

    /// Marks a row whose sample failed: a red caption and no tiles.
    pub fn failed_row(&mut self, row: u32, caption: &str) {
        let y0 = LINE_H + row * (LINE_H + self.tile_h + GAP);
        self.text(GAP + 2, y0 + 2, caption, [255, 80, 80]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_and_text_land_where_expected() {
        let mut sheet = Sheet::new(2, 16, 8);
        assert_eq!(sheet.width, 6 * 18 + 2);
        assert_eq!(sheet.height, 12 + 2 * (12 + 8 + 2) + 2);
        // The header's first glyph ('l') has lit pixels inside the first tile column.
        let lit = |s: &Sheet, x0: u32, y0: u32, w: u32, h: u32, c: [u8; 3]| {
            (y0..y0 + h).any(|y| {
                (x0..x0 + w).any(|x| {
                    let k = ((y * s.width + x) * 3) as usize;
                    s.pixels[k..k + 3] == c
                })
            })
        };
        assert!(lit(&sheet, 4, 2, 8, 8, [255, 255, 255]));
        let tile = vec![[10, 200, 30]; 16 * 8];
        sheet.row(1, "x", &vec![tile; 6]);
        let y_tiles = 12 + (12 + 8 + 2) + 12;
        assert!(lit(&sheet, 2, y_tiles, 16, 8, [10, 200, 30]));
        // Row 0 stays empty of tile colour.
        assert!(!lit(&sheet, 0, 12, sheet.width, 22, [10, 200, 30]));
        // Text past the right edge is clipped, not a panic.
        sheet.text(sheet.width - 4, 0, "clipped", [1, 2, 3]);
    }
}
