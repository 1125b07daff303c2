//! A contact sheet: frames side by side, each labelled with its tilt in a
//! built-in 5 × 7 pixel font (digits, sign, point and degree sign).

use glam::DVec3;

/// 8-bit RGB image, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgb8 {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<[u8; 3]>,
}

impl Rgb8 {
    /// The pixels as bytes, R, G, B per pixel.
    pub fn bytes(&self) -> &[u8] {
        self.pixels.as_flattened()
    }
}

/// Linear colours (1 = a light's full radiance) to 8 bits per channel,
/// clamped; values are stored linearly, as the tracer computes them.
pub fn to_rgb8(width: usize, height: usize, rgb: &[DVec3]) -> Rgb8 {
    Rgb8 {
        width,
        height,
        pixels: rgb
            .iter()
            .map(|c| {
                c.to_array()
                    .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            })
            .collect(),
    }
}

/// Glyph rows (5 bits each, most significant = leftmost column).
fn glyph(c: char) -> [u8; 7] {
    match c {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        '°' => [0x0C, 0x12, 0x12, 0x0C, 0x00, 0x00, 0x00],
        _ => [0; 7],
    }
}

/// Height of a label strip (pixels) at scale 2.
const LABEL_HEIGHT: usize = 20;

/// Frames in a row-major grid of `columns`, each with its label under it.
pub fn contact_sheet(frames: &[(Rgb8, String)], columns: usize) -> Rgb8 {
    let (fw, fh) = frames.first().map_or((0, 0), |(g, _)| (g.width, g.height));
    let (gap, columns) = (4, columns.max(1));
    let rows = frames.len().div_ceil(columns);
    let (width, height) = (
        columns * (fw + gap) + gap,
        rows * (fh + LABEL_HEIGHT + gap) + gap,
    );
    let mut pixels = vec![[255u8; 3]; width * height];
    for (i, (frame, label)) in frames.iter().enumerate() {
        let (x0, y0) = (
            gap + (i % columns) * (fw + gap),
            gap + (i / columns) * (fh + LABEL_HEIGHT + gap),
        );
        for y in 0..fh {
            pixels[(y0 + y) * width + x0..(y0 + y) * width + x0 + fw]
                .copy_from_slice(&frame.pixels[y * fw..(y + 1) * fw]);
        }
        // the label centred under the frame, at scale 2 where it fits with
        // room to spare (labels of neighbouring frames must not touch)
        let scale = if label.chars().count() * 12 + 8 <= fw {
            2
        } else {
            1
        };
        let text_w = label.chars().count() * 6 * scale;
        let tx = x0 + fw.saturating_sub(text_w) / 2;
        let ty = y0 + fh + (LABEL_HEIGHT - 7 * scale) / 2;
        for (k, c) in label.chars().enumerate() {
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        for (dy, dx) in (0..scale).flat_map(|a| (0..scale).map(move |b| (a, b))) {
                            let (x, y) = (tx + (k * 6 + col) * scale + dx, ty + row * scale + dy);
                            if x < width && y < height {
                                pixels[y * width + x] = [0; 3];
                            }
                        }
                    }
                }
            }
        }
    }
    Rgb8 {
        width,
        height,
        pixels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_and_labels_land_where_they_should() {
        let frame = Rgb8 {
            width: 10,
            height: 8,
            pixels: vec![[128, 64, 32]; 80],
        };
        let sheet = contact_sheet(
            &[(frame.clone(), "-5.0°".into()), (frame, "+5.0°".into())],
            2,
        );
        assert_eq!(
            (sheet.width, sheet.height),
            (2 * 14 + 4, 8 + LABEL_HEIGHT + 8)
        );
        assert_eq!(sheet.pixels[4 * sheet.width + 4], [128, 64, 32]);
        assert!(
            sheet.pixels[(8 + 4)..].contains(&[0; 3]),
            "labels are drawn"
        );
        assert_eq!(
            to_rgb8(1, 1, &[DVec3::new(-1.0, 0.5, 2.0)]).pixels,
            vec![[0, 128, 255]]
        );
    }
}
