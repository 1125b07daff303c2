//! The spec's file habits: Save, Save as, Open, and the files the page may
//! pick (the specs and the PNG images in the spec's folder).
//!
//! Every name the page sends is one plain file name inside the spec's
//! folder (the spec file's, or `-o DIR` for the built-in design): no path,
//! no `..`, no hidden file. Save as never replaces another file unless
//! asked to (`replace=true`, after the page's confirmation).

use super::{blocking, error, make_current, refused, Home, Studio};
use axum::extract::{Query, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Deserialize;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The folder a spec lives in: its file's, or `out` for the built-in
/// design (which Save writes as `out/spec.toml`).
pub(super) fn folder(home: &Home, out: &Path) -> PathBuf {
    match home {
        Home::File { dir, .. } => dir.clone(),
        Home::Embedded => out.to_owned(),
    }
}

/// The longest spec file name the page may give.
const MAX_NAME_CHARS: usize = 100;

/// `name` as a spec file name in the folder: one plain component of
/// letters, digits, spaces, `-`, `_` and `.`, not hidden, ending in
/// `.toml` (added when it has no extension); or why not, in the page's
/// words.
pub(super) fn spec_name(name: &str) -> Result<String, String> {
    let name = name.trim();
    let plain = |c: char| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_' | '.');
    if name.is_empty()
        || name.starts_with('.')
        || name.chars().count() > MAX_NAME_CHARS
        || !name.chars().all(plain)
    {
        return Err(format!(
            "{name:?} is not a spec file name: use letters, digits, spaces, - and _ (at most {MAX_NAME_CHARS} characters), no folders, ending in .toml"
        ));
    }
    Ok(match Path::new(name).extension() {
        Some(e) if e == "toml" => name.to_owned(),
        Some(_) => return Err(format!("{name:?} is not a .toml file name")),
        None => format!("{name}.toml"),
    })
}

/// Writes `text` as `dir/name` (through a temporary file renamed in), and,
/// for the built-in design, the embedded images it names beside it.
fn write_spec(home: &Home, text: &str, dir: &Path, name: &str) -> anyhow::Result<PathBuf> {
    let mut files = moirecast_export::OutputSet::new();
    files.add(name, text.as_bytes().to_vec());
    let mut written = files.commit(dir)?;
    if let Home::Embedded = home {
        for (image, data) in moirecast_spec::embedded_images() {
            if text.contains(image) {
                let path = dir.join(image);
                let mut one = moirecast_export::OutputSet::new();
                let file = path.file_name().expect("an image name").to_string_lossy();
                one.add(&file, data.to_vec());
                one.commit(path.parent().expect("inside DIR"))?;
            }
        }
    }
    Ok(written.remove(0))
}

/// Writes the current spec's text to the spec file (or `DIR/spec.toml`
/// with the embedded images it names, for the reference design).
pub(super) async fn save(State(studio): State<Arc<Studio>>) -> Response {
    let rev = studio.current();
    let home = studio.home();
    let (dir, name) = match &home {
        Home::File { path, dir } => (
            dir.clone(),
            path.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "spec.toml".into()),
        ),
        Home::Embedded => (studio.out.clone(), "spec.toml".to_string()),
    };
    let result = blocking(move || write_spec(&home, &rev.text, &dir, &name)).await;
    match result {
        Ok(path) => Json(json!({"saved": path.display().to_string()})).into_response(),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, format!("{e:#}")),
    }
}

/// `?name=NAME&replace=true` of Save as.
#[derive(Deserialize)]
pub(super) struct SaveAs {
    name: String,
    #[serde(default)]
    replace: bool,
}

/// Writes the current spec's text as `name` in the spec's folder, which
/// then becomes the spec file (Save writes there, images resolve beside
/// it). Another existing file is replaced only with `replace=true`: 409
/// says it exists.
pub(super) async fn save_as(
    State(studio): State<Arc<Studio>>,
    Query(q): Query<SaveAs>,
) -> Response {
    let name = match spec_name(&q.name) {
        Ok(name) => name,
        Err(why) => return error(StatusCode::BAD_REQUEST, why),
    };
    let home = studio.home();
    let dir = folder(&home, &studio.out);
    let path = dir.join(&name);
    let same = matches!(&home, Home::File { path: p, .. } if *p == path);
    if path.exists() && !same && !q.replace {
        let message = format!("{name} already exists in {}: replace it?", dir.display());
        return (
            StatusCode::CONFLICT,
            Json(json!({"error": message, "exists": true})),
        )
            .into_response();
    }
    let rev = studio.current();
    let (text, at) = (rev.text.clone(), dir.clone());
    let written = blocking(move || write_spec(&home, &text, &at, &name)).await;
    match written {
        Ok(saved) => {
            *studio.home.write().expect("not poisoned") = Home::File {
                path: saved.clone(),
                dir,
            };
            let state = studio.state(&rev);
            Json(json!({"saved": saved.display().to_string(), "state": state})).into_response()
        }
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, format!("{e:#}")),
    }
}

/// The spec files (`*.toml`) in the spec's folder, sorted, and the folder.
pub(super) async fn specs(State(studio): State<Arc<Studio>>) -> Json<serde_json::Value> {
    let dir = folder(&studio.home(), &studio.out);
    let mut found: Vec<String> = std::fs::read_dir(&dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter_map(|e| e.file_name().to_str().map(str::to_owned))
        .filter(|n| spec_name(n).as_deref() == Ok(n.as_str()))
        .collect();
    found.sort();
    Json(json!({"folder": dir.display().to_string(), "specs": found}))
}

/// `?name=NAME` of Open.
#[derive(Deserialize)]
pub(super) struct OpenSpec {
    name: String,
}

/// Opens the spec `name` of the spec's folder: a valid design becomes the
/// current revision and the spec file (200 with the state); an invalid one
/// is refused by key (422) and nothing changes.
pub(super) async fn open(State(studio): State<Arc<Studio>>, Query(q): Query<OpenSpec>) -> Response {
    let name = match spec_name(&q.name) {
        Ok(name) => name,
        Err(why) => return error(StatusCode::BAD_REQUEST, why),
    };
    let dir = folder(&studio.home(), &studio.out);
    let path = dir.join(&name);
    if !super::is_inside(&dir, Path::new(&name)) {
        return error(
            StatusCode::NOT_FOUND,
            format!("no spec {name} in {}", dir.display()),
        );
    }
    let home = Home::File { path, dir };
    let parsed = {
        let (studio, home) = (studio.clone(), home.clone());
        blocking(move || -> Result<_, Vec<serde_json::Value>> {
            let text = read_spec(&home)?;
            let spec = studio.parse_at(&home, &text)?;
            Ok((text, spec))
        })
        .await
    };
    match parsed {
        Err(errors) => refused(&studio, errors),
        Ok((text, spec)) => {
            *studio.home.write().expect("not poisoned") = home;
            make_current(&studio, text, spec)
        }
    }
}

/// The text of the spec file at `home`, within the studio's body limit.
fn read_spec(home: &Home) -> Result<String, Vec<serde_json::Value>> {
    let Home::File { path, .. } = home else {
        return Ok(moirecast_spec::DEFAULT_SPEC.to_owned());
    };
    let unreadable = |why: String| {
        vec![
            json!({"key": null, "value": null, "message": why, "fix": "open another spec", "cli": why}),
        ]
    };
    let size = std::fs::metadata(path).map_err(|e| unreadable(e.to_string()))?;
    if size.len() > super::MAX_BODY_BYTES as u64 {
        return Err(unreadable(format!(
            "{} is larger than a spec may be ({} bytes)",
            path.display(),
            super::MAX_BODY_BYTES
        )));
    }
    std::fs::read_to_string(path).map_err(|e| unreadable(format!("{}: {e}", path.display())))
}

/// The PNG images the spec may name: inside its folder, two levels deep.
pub(super) async fn profiles(State(studio): State<Arc<Studio>>) -> Json<Vec<String>> {
    let found = match studio.home() {
        Home::Embedded => moirecast_spec::embedded_images()
            .map(|(n, _)| n.to_string())
            .collect(),
        Home::File { dir, .. } => {
            let mut found = Vec::new();
            let pngs = |sub: &Path, found: &mut Vec<String>, dirs: &mut Vec<PathBuf>| {
                for entry in std::fs::read_dir(dir.join(sub))
                    .into_iter()
                    .flatten()
                    .flatten()
                {
                    let name = sub.join(entry.file_name());
                    match entry.file_type() {
                        Ok(t) if t.is_dir() => dirs.push(name),
                        Ok(_)
                            if name
                                .extension()
                                .is_some_and(|e| e.eq_ignore_ascii_case("png")) =>
                        {
                            found.push(name.display().to_string())
                        }
                        _ => {}
                    }
                }
            };
            let mut dirs = Vec::new();
            pngs(Path::new(""), &mut found, &mut dirs);
            for sub in dirs {
                pngs(&sub, &mut found, &mut Vec::new());
            }
            found.sort();
            found
        }
    };
    Json(found)
}
