//! 3MF (3D Manufacturing Format, core specification 1.3): one build of
//! several objects, each with its own base material and display colour —
//! the format slicers read for multi-material parts.

use crate::ExportError;
use moirecast_kernel::check::SolidMesh;
use std::fmt::Write as _;
use std::io::Write as _;

/// A material of a 3MF base-material group.
#[derive(Clone, Copy, Debug)]
pub struct Material {
    pub name: &'static str,
    /// sRGB colour and alpha, as 3MF's `#RRGGBBAA`.
    pub display_color: [u8; 4],
}

/// One object of the build: a validated solid in one material.
pub struct Object<'a> {
    pub name: &'static str,
    pub solid: SolidMesh<'a>,
    pub material: Material,
}

const CONTENT_TYPES: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">
 <Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>
 <Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>
</Types>
"#;

const RELS: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">
 <Relationship Target="/3D/3dmodel.model" Id="rel0" Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/>
</Relationships>
"#;

/// The 3D model part: a base-material group, one object per solid (its
/// vertices as the f32 values STL stores, so both files hold the same
/// solid), and a build with every object.
pub fn model_xml(objects: &[Object]) -> String {
    let mut x = String::new();
    x.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    x.push_str("<model unit=\"millimeter\" xml:lang=\"en-US\" xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\">\n");
    let _ = writeln!(
        x,
        " <metadata name=\"Application\">moirecast {}</metadata>",
        env!("CARGO_PKG_VERSION")
    );
    x.push_str(" <resources>\n  <basematerials id=\"1\">\n");
    for o in objects {
        let [r, g, b, a] = o.material.display_color;
        let _ = writeln!(
            x,
            "   <base name=\"{}\" displaycolor=\"#{r:02X}{g:02X}{b:02X}{a:02X}\"/>",
            o.material.name
        );
    }
    x.push_str("  </basematerials>\n");
    for (i, o) in objects.iter().enumerate() {
        let mesh = o.solid.mesh();
        let _ = writeln!(
            x,
            "  <object id=\"{}\" type=\"model\" name=\"{}\" pid=\"1\" pindex=\"{i}\">\n   <mesh>\n    <vertices>",
            i + 2,
            o.name
        );
        x.push_str(&in_parallel(&mesh.positions, |x, p| {
            let _ = writeln!(
                x,
                "     <vertex x=\"{}\" y=\"{}\" z=\"{}\"/>",
                p.x as f32, p.y as f32, p.z as f32
            );
        }));
        x.push_str("    </vertices>\n    <triangles>\n");
        x.push_str(&in_parallel(&mesh.triangles, |x, [a, b, c]| {
            let _ = writeln!(x, "     <triangle v1=\"{a}\" v2=\"{b}\" v3=\"{c}\"/>");
        }));
        x.push_str("    </triangles>\n   </mesh>\n  </object>\n");
    }
    x.push_str(" </resources>\n <build>\n");
    for i in 0..objects.len() {
        let _ = writeln!(x, "  <item objectid=\"{}\"/>", i + 2);
    }
    x.push_str(" </build>\n</model>\n");
    x
}

/// `write` applied to every item, in chunks on all threads, concatenated in order.
fn in_parallel<T: Sync>(items: &[T], write: impl Fn(&mut String, &T) + Sync) -> String {
    use rayon::prelude::*;
    let chunks: Vec<String> = items
        .par_chunks(16384)
        .map(|chunk| {
            let mut x = String::with_capacity(64 * chunk.len());
            for item in chunk {
                write(&mut x, item);
            }
            x
        })
        .collect();
    chunks.concat()
}

/// Encodes `objects` as a 3MF package. Deterministic: fixed entry order
/// and timestamps.
pub fn threemf_bytes(file: &str, objects: &[Object]) -> Result<Vec<u8>, ExportError> {
    let io = |source: std::io::Error| ExportError::Io {
        path: file.into(),
        source,
    };
    let zip_err = |e: zip::result::ZipError| io(std::io::Error::other(e));
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        // level 1: a third bigger than the default, several times faster
        .compression_level(Some(1))
        .last_modified_time(zip::DateTime::default())
        .unix_permissions(0o644);
    for (name, text) in [
        ("[Content_Types].xml", CONTENT_TYPES.to_string()),
        ("_rels/.rels", RELS.to_string()),
        ("3D/3dmodel.model", model_xml(objects)),
    ] {
        zip.start_file(name, options).map_err(zip_err)?;
        zip.write_all(text.as_bytes()).map_err(io)?;
    }
    Ok(zip.finish().map_err(zip_err)?.into_inner())
}
