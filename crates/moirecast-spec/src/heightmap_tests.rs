//! `kind = "heightmap"`: a known answer against the closed-form saddle,
//! and every bad input refused by its key.

use super::*;

/// A fresh folder for one test.
fn folder(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("moirecast-spec-hm-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("surfaces")).unwrap();
    dir
}

/// A 16-bit greyscale PNG of `f` over `size` mm (pixel centres), black at
/// `z_min` and white at `z_max`.
fn png16(
    path: &Path,
    pixels: u32,
    size: f64,
    (z_min, z_max): (f64, f64),
    f: impl Fn(f64, f64) -> f64,
) {
    let step = size / f64::from(pixels);
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(pixels, pixels, |i, j| {
        let x = -size / 2.0 + (f64::from(i) + 0.5) * step;
        let y = size / 2.0 - (f64::from(j) + 0.5) * step;
        image::Luma([((f(x, y) - z_min) / (z_max - z_min) * 65535.0).round() as u16])
    });
    img.save(path).unwrap();
}

const SADDLE_R: f64 = 60.0;

fn saddle(x: f64, y: f64) -> f64 {
    (x * x - y * y) / (2.0 * SADDLE_R)
}

/// The reference layout on `surface` (a `[surface]` table's body).
fn spec_on(surface: &str) -> String {
    format!("[surface]\n{surface}\n[layout]\nwidth = 40.0\nheight = 30.0\n[profile]\nkind = \"rings\"\nwavelength = 8.0\n")
}

/// A height map sampled from the saddle's own formula (16 bit, 0.25 mm
/// pixels) builds a design whose revealer and base lenses lie within the
/// mesh tolerance of the closed-form saddle's.
#[test]
fn a_saddle_height_map_gives_the_saddle_s_lenses() {
    let dir = folder("known");
    let (size, z) = (44.0, (-4.1, 4.1));
    png16(&dir.join("surfaces/saddle.png"), 176, size, z, saddle);
    let text = spec_on(&format!(
        "kind = \"heightmap\"\nimage = \"surfaces/saddle.png\"\nz_min = {}\nz_max = {}\nsize = [{size}, {size}]",
        z.0, z.1
    ));
    let map = parse(&text, "hm.toml", ImageSource::Dir(&dir)).unwrap();
    let exact = parse(
        &spec_on("kind = \"saddle\"\nradius = 60.0"),
        "s.toml",
        ImageSource::Embedded,
    )
    .unwrap();
    let (a, b) = (&map.design, &exact.design);
    assert_eq!((a.lenses, a.params.period), (b.lenses, b.params.period));
    let tolerance = b.tolerance.mm();
    let mut worst = 0.0f64;
    for i in (0..a.lenses as i64).step_by(7) {
        for v in [-14.0, -6.5, 0.0, 9.25, 14.5] {
            for t in [0.0, 0.25, 0.5, 0.8] {
                worst = worst.max((a.revealer_point(i, t, v) - b.revealer_point(i, t, v)).length());
                let (pa, pb) = (
                    a.base_point(i, t, v).unwrap(),
                    b.base_point(i, t, v).unwrap(),
                );
                worst = worst.max((pa - pb).length());
            }
        }
    }
    eprintln!("lens points within {worst:.2e} mm of the saddle's");
    assert!(
        worst < tolerance,
        "lens points {worst:.2e} mm off the saddle's (tolerance {tolerance} mm)"
    );
    let PitchSurface::HeightMap(m) = &a.params.surface else {
        panic!("a height map")
    };
    // 16-bit steps of 0.13 µm, smoothed over 8 pixels by default
    assert!(m.max_deviation() < 5e-4 && m.smoothing() == 2.0, "{m:?}");
    assert_eq!(map.source.images.len(), 1);
    assert_eq!(map.source.images[0].key, "surface.image");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Each bad input is refused by the key it came from, with a fix.
#[test]
fn bad_height_maps_are_refused_by_key() {
    let dir = folder("bad");
    png16(
        &dir.join("surfaces/ok.png"),
        32,
        44.0,
        (0.0, 1.0),
        |_, _| 0.5,
    );
    png16(
        &dir.join("surfaces/tiny.png"),
        1,
        44.0,
        (0.0, 1.0),
        |_, _| 0.5,
    );
    std::fs::write(
        dir.join("surfaces/corrupt.png"),
        b"\x89PNG\r\n\x1a\nnot a png",
    )
    .unwrap();
    // a header that claims 100 000 × 100 000 pixels, over a few bytes
    let chunk = |kind: &[u8], data: &[u8]| {
        let mut c = (data.len() as u32).to_be_bytes().to_vec();
        c.extend(kind);
        c.extend(data);
        c.extend(crc32(&c[4..]).to_be_bytes());
        c
    };
    let mut header = 100_000u32.to_be_bytes().to_vec();
    header.extend(100_000u32.to_be_bytes());
    header.extend([16, 0, 0, 0, 0]);
    let mut bomb = b"\x89PNG\r\n\x1a\n".to_vec();
    bomb.extend(chunk(b"IHDR", &header));
    bomb.extend(chunk(
        b"IDAT",
        &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    ));
    bomb.extend(chunk(b"IEND", &[]));
    std::fs::write(dir.join("surfaces/bomb.png"), bomb).unwrap();
    let hm = |body: &str| spec_on(&format!("kind = \"heightmap\"\n{body}"));
    let ok = "z_min = 0.0\nz_max = 1.0";
    for (text, key, words) in [
        (
            hm(&format!("image = \"surfaces/missing.png\"\n{ok}")),
            "surface.image",
            "cannot read",
        ),
        (
            hm(&format!("image = \"surfaces/corrupt.png\"\n{ok}")),
            "surface.image",
            "not a readable image",
        ),
        (
            hm(&format!("image = \"surfaces/bomb.png\"\n{ok}")),
            "surface.image",
            "at most",
        ),
        (
            hm(&format!("image = \"surfaces/tiny.png\"\n{ok}")),
            "surface.image",
            "at least 4 × 4",
        ),
        (hm(ok), "surface.image", "needs a greyscale PNG"),
        (
            hm("image = \"surfaces/ok.png\"\nz_min = 2.0"),
            "surface.z_max",
            "below surface.z_min",
        ),
        (
            hm("image = \"surfaces/ok.png\"\nz_min = 2.0\nz_max = 1.0"),
            "surface.z_max",
            "below surface.z_min",
        ),
        (
            hm(&format!(
                "image = \"surfaces/ok.png\"\n{ok}\nsize = [30.0, 30.0]"
            )),
            "surface.size",
            "must cover the layout",
        ),
        (
            hm(&format!(
                "image = \"surfaces/ok.png\"\n{ok}\nsmoothing = -1.0"
            )),
            "surface.smoothing",
            "zero or positive",
        ),
        (
            spec_on("kind = \"saddle\"\nz_max = 1.0"),
            "surface.z_max",
            "only used with kind = \"heightmap\"",
        ),
    ] {
        let Err(e) = parse(&text, "bad.toml", ImageSource::Dir(&dir)) else {
            panic!("{text}: accepted")
        };
        let SpecError::Invalid {
            key: got,
            problem,
            fix,
            ..
        } = &e
        else {
            panic!("{text}: {e}")
        };
        assert!(
            got == &key && problem.contains(words) && !fix.is_empty(),
            "{text}: {e}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// PNG's chunk checksum (CRC-32, ISO 3309).
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}
