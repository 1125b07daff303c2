//! STEP (ISO 10303-21) text of a B-rep, written by truck-stepio with a
//! clean, deterministic header, and read back by truck-stepio.

use crate::error::BrepError;
use truck_modeling::Solid;
use truck_stepio::out::{CompleteStepDisplay, StepHeaderDescriptor, StepModels};

/// The timestamp written into every header: outputs are deterministic, so
/// the file carries no clock reading (ISO 8601, as STEP asks).
pub const STEP_TIMESTAMP: &str = "2000-01-01T00:00:00";

/// The STEP text of `solid`, as file `file_name`.
///
/// truck-stepio 0.3 wraps the author and organization lists in a second
/// pair of parentheses (`(('x'))`), which OpenCascade reports as an error,
/// and stamps the current time; the header is therefore written here.
pub fn step_text(solid: &Solid, file_name: &str, description: &str) -> String {
    step_text_of(std::slice::from_ref(solid), file_name, description)
}

/// The STEP text of several `solids` in one file (each its own solid), as
/// file `file_name`, with the same header as [`step_text`].
pub fn step_text_of(solids: &[Solid], file_name: &str, description: &str) -> String {
    let compressed: Vec<_> = solids.iter().map(|s| s.compress()).collect();
    let text = CompleteStepDisplay::new(
        compressed.iter().collect::<StepModels<_, _, _>>(),
        StepHeaderDescriptor {
            file_name: file_name.into(),
            time_stamp: STEP_TIMESTAMP.into(),
            ..Default::default()
        },
    )
    .to_string();
    with_header(&text, file_name, description)
}

/// `text` (truck-stepio's) with the header written here.
fn with_header(text: &str, file_name: &str, description: &str) -> String {
    let data = text
        .find("DATA;\n")
        .expect("truck-stepio writes a DATA section");
    let schema = text[..data]
        .lines()
        .find(|l| l.starts_with("FILE_SCHEMA("))
        .expect("truck-stepio writes FILE_SCHEMA")
        .to_owned();
    let escape = |s: &str| s.replace('\'', "''");
    format!(
        "ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('{}'), '2;1');\nFILE_NAME('{}', '{}', ('moirecast'), ('moirecast'), 'truck-stepio 0.3', 'moirecast {}', '');\n{}\nENDSEC;\n{}",
        escape(description),
        escape(file_name),
        STEP_TIMESTAMP,
        env!("CARGO_PKG_VERSION"),
        schema,
        &text[data..]
    )
}

/// Reads STEP text back with truck-stepio and returns the face count of
/// each shell in it.
pub fn read_back_faces(text: &str) -> Result<Vec<usize>, BrepError> {
    use truck_stepio::r#in::Table;
    let table = Table::from_step(text)
        .ok_or_else(|| BrepError::StepRoundTrip("truck-stepio could not parse the text".into()))?;
    let mut shells: Vec<_> = table.shell.iter().collect();
    shells.sort_by_key(|(id, _)| **id);
    shells
        .into_iter()
        .map(|(id, holder)| {
            table
                .to_compressed_shell(holder)
                .map(|s| s.faces.len())
                .map_err(|e| BrepError::StepRoundTrip(format!("shell #{id}: {e}")))
        })
        .collect()
}
