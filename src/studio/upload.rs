//! An image dropped on the page, added to the spec's folder: read as a PNG
//! within a pixel budget, named safely inside `profiles/` (a profile) or
//! `surfaces/` (a height map), written whole (a temporary renamed in) or
//! not at all.

use std::path::Path;

/// The most pixels an added image may have (a 1 MB body can hold a PNG
/// that decodes to gigabytes): a spec's own budget.
pub const MAX_IMAGE_PIXELS: u64 = moirecast_spec::MAX_IMAGE_PIXELS;

/// The longest file stem an added image keeps.
const MAX_STEM_CHARS: usize = 64;

/// The folder an added image goes to: `profiles` or `surfaces`.
#[derive(Clone, Copy, Debug)]
pub(super) enum ImageFolder {
    Profiles,
    Surfaces,
}

impl ImageFolder {
    fn name(self) -> &'static str {
        match self {
            ImageFolder::Profiles => "profiles",
            ImageFolder::Surfaces => "surfaces",
        }
    }
}

/// Adds the PNG `bytes`, dropped as a file named `given`, to `dir`'s
/// `to` folder and returns its path relative to `dir` (as a spec names
/// it): the same bytes already there are reused, another file of that
/// name is never replaced (`-2`, `-3`, … is added).
pub(super) fn add_image(
    dir: &Path,
    to: ImageFolder,
    given: &str,
    bytes: &[u8],
) -> Result<String, String> {
    check_png(bytes)?;
    let stem = safe_stem(given);
    let sub = to.name();
    let folder = dir.join(sub);
    std::fs::create_dir_all(&folder)
        .map_err(|e| format!("cannot make {}: {e}", folder.display()))?;
    for n in 1..1000 {
        let name = match n {
            1 => format!("{stem}.png"),
            _ => format!("{stem}-{n}.png"),
        };
        let path = folder.join(&name);
        match std::fs::read(&path) {
            Ok(there) if there == bytes => return Ok(format!("{sub}/{name}")),
            Ok(_) => continue,
            Err(_) if path.exists() => continue,
            Err(_) => {}
        }
        let temporary = folder.join(format!(".{name}.{}.tmp", std::process::id()));
        let written = std::fs::write(&temporary, bytes)
            .and_then(|()| std::fs::rename(&temporary, &path))
            .map_err(|e| format!("cannot write {}: {e}", path.display()));
        if written.is_err() {
            let _ = std::fs::remove_file(&temporary);
        }
        return written.map(|()| format!("{sub}/{name}"));
    }
    Err(format!("{sub}/ already holds 999 images named {stem}"))
}

/// Whether `bytes` are a PNG image of at most [`MAX_IMAGE_PIXELS`] that
/// decodes whole; the reason if not, in the page's words.
fn check_png(bytes: &[u8]) -> Result<(), String> {
    let not_png = |e: image::ImageError| format!("not a readable PNG image: {e}");
    let reader =
        image::ImageReader::with_format(std::io::Cursor::new(bytes), image::ImageFormat::Png);
    let (w, h) = reader.into_dimensions().map_err(not_png)?;
    if u64::from(w) * u64::from(h) > MAX_IMAGE_PIXELS {
        return Err(format!(
            "the image is {w} × {h} pixels: at most {MAX_IMAGE_PIXELS} pixels (4096 × 4096)"
        ));
    }
    image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
        .map(|_| ())
        .map_err(not_png)
}

/// A file stem from a dropped file's name: its last path part without the
/// extension, letters, digits, `-` and `_` kept, every other run of
/// characters one `-`, at most [`MAX_STEM_CHARS`]; `image` if nothing is left.
fn safe_stem(given: &str) -> String {
    let last = given.rsplit(['/', '\\']).next().unwrap_or("");
    let stem = last
        .strip_suffix(".png")
        .or_else(|| last.strip_suffix(".PNG"))
        .unwrap_or(last);
    let mut safe = String::new();
    for c in stem.chars() {
        if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
            safe.push(c);
        } else if !safe.ends_with('-') {
            safe.push('-');
        }
    }
    let safe: String = safe
        .trim_matches('-')
        .chars()
        .take(MAX_STEM_CHARS)
        .collect();
    if safe.is_empty() {
        "image".into()
    } else {
        safe
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dropped_name_stays_inside_profiles() {
        assert_eq!(safe_stem("../../etc/passwd"), "passwd");
        assert_eq!(safe_stem("C:\\maps\\my map (2).png"), "my-map-2");
        assert_eq!(safe_stem(".png"), "image");
        assert_eq!(safe_stem("...."), "image");
        assert_eq!(safe_stem(&"a".repeat(300)).len(), MAX_STEM_CHARS);
    }
}
