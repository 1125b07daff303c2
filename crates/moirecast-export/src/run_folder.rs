//! An output folder holds exactly one run.
//!
//! A run's files are written into a fresh staging folder beside `DIR`
//! (`.DIR.moirecast-PID-N.new`, on the same file system), with a manifest
//! (`.moirecast-run`) that lists every file (report.json gives their
//! SHA-256s: [`crate::OutputSet::digests`]). Then two
//! renames swap it in: `DIR` → `.DIR.moirecast-PID.old`, the staging folder
//! → `DIR`; and the old folder is removed. A reader sees the old run, or no
//! folder for the instant between the renames, or the new run: never a mix.
//!
//! A process killed at any moment leaves at most those sibling folders, and
//! the next run into `DIR` recovers first, under a lock: where `DIR` is
//! missing, a complete staging folder (its manifest written last) is
//! renamed in, else the old one back; every other staging or old folder,
//! and the single-file temporaries of earlier versions, are removed.
//!
//! A folder is replaced only if it is empty or a run's (its manifest lists
//! every file in it; a run of a version before manifests is recognised by
//! its report.json, and only files of the names runs write count as its).
//! The studio's saved spec (`spec.toml`) and the images
//! it names (`profiles/`) are the one exception, and are carried over into
//! the new run; anything else that no run wrote makes the run refuse
//! before writing, so a user's own files are never deleted.

use crate::{ExportError, FileContent};
use std::path::{Path, PathBuf};

/// The manifest inside a run's folder: a file's name per line.
pub const MANIFEST: &str = ".moirecast-run";

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ExportError + '_ {
    move |source| ExportError::Io {
        path: path.to_owned(),
        source,
    }
}

/// `DIR`'s parent and the prefix of its sibling folders.
fn siblings(dir: &Path) -> (PathBuf, String) {
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
        _ => PathBuf::from("."),
    };
    let name = dir
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    (parent, format!(".{name}.moirecast-"))
}

/// The hex SHA-256 of a staged file's bytes.
pub fn sha256(content: &dyn FileContent) -> String {
    use sha2::{Digest, Sha256};
    let mut hasher = Sha256::new();
    for piece in content.pieces() {
        hasher.update(piece);
    }
    hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The files a run's manifest lists, or `None` if `dir` has no manifest.
fn manifest_files(dir: &Path) -> Option<Vec<String>> {
    let text = std::fs::read_to_string(dir.join(MANIFEST)).ok()?;
    Some(
        text.lines()
            .filter(|l| !l.is_empty())
            .map(str::to_owned)
            .collect(),
    )
}

/// The files of the run in `dir` that a run into it would replace (its
/// manifest's, or an earlier version's output files; the carried spec
/// aside), sorted; empty where `dir` holds no run. Read before a run, it
/// says what the run replaces.
pub fn earlier_run(dir: &Path) -> Vec<String> {
    let mut files = manifest_files(dir).unwrap_or_else(|| {
        if is_earlier_run(dir) {
            files_under(dir)
                .into_iter()
                .filter(|f| is_output_name(f))
                .collect()
        } else {
            Vec::new()
        }
    });
    files.retain(|f| !carried(f));
    files.sort();
    files
}

/// Every file under `dir`, relative, `/`-separated.
fn files_under(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(sub) = stack.pop() {
        for entry in std::fs::read_dir(dir.join(&sub))
            .into_iter()
            .flatten()
            .flatten()
        {
            let rel = sub.join(entry.file_name());
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(rel);
            } else {
                found.push(rel.to_string_lossy().replace('\\', "/"));
            }
        }
    }
    found.sort();
    found
}

/// Whether `dir` holds a run of a moirecast before manifests: a
/// report.json of moirecast's (its `"moirecast"` version key).
fn is_earlier_run(dir: &Path) -> bool {
    std::fs::read_to_string(dir.join("report.json"))
        .is_ok_and(|r| r.trim_start().starts_with('{') && r.contains("\"moirecast\": \""))
}

/// Whether a file's name is one moirecast's runs write (for folders of
/// earlier runs, which have no manifest): only those are replaced.
fn is_output_name(name: &str) -> bool {
    let stem_ext = |stem: &str, exts: &[&str]| {
        name.strip_prefix(stem)
            .is_some_and(|rest| exts.iter().any(|e| rest.ends_with(e)) && !rest.contains('/'))
    };
    [
        "report.json",
        "tilt.gif",
        "sheet.png",
        "grid.png",
        "best.toml",
        "assembly.scad",
    ]
    .contains(&name)
        || stem_ext("device", &[".stl", ".step", ".3mf"])
        || stem_ext("mold-", &[".stl", ".step"])
        || stem_ext("construction-", &[".stl"])
        || stem_ext("frame-", &[".png"])
        || (name.starts_with('.') && name.ends_with(".tmp"))
}

/// A file of the studio's saved spec, which a run carries over.
fn carried(name: &str) -> bool {
    name == "spec.toml" || name.starts_with("profiles/")
}

/// Finishes or undoes what a killed run left beside `dir`, and removes its
/// temporaries. Call under the lock.
fn recover(dir: &Path) -> Result<(), ExportError> {
    let (parent, prefix) = siblings(dir);
    let mut leftovers: Vec<PathBuf> = std::fs::read_dir(&parent)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.starts_with(&prefix) && (n.ends_with(".new") || n.ends_with(".old"))
        })
        .map(|e| e.path())
        .collect();
    leftovers.sort();
    if !dir.exists() {
        let complete_new = leftovers
            .iter()
            .find(|p| p.to_string_lossy().ends_with(".new") && p.join(MANIFEST).is_file());
        let old = leftovers
            .iter()
            .find(|p| p.to_string_lossy().ends_with(".old"));
        if let Some(back) = complete_new.or(old) {
            std::fs::rename(back, dir).map_err(io(dir))?;
        }
    }
    for stale in leftovers.iter().filter(|p| p.exists()) {
        std::fs::remove_dir_all(stale).map_err(io(stale))?;
    }
    // single-file temporaries of earlier versions: `.NAME.PID.tmp`
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let n = entry.file_name().to_string_lossy().into_owned();
        if n.starts_with('.') && n.ends_with(".tmp") && n != MANIFEST {
            std::fs::remove_file(entry.path()).map_err(io(&entry.path()))?;
        }
    }
    Ok(())
}

/// The files in `dir` that a run would carry over, or why the folder is
/// not a run's to replace.
fn replaceable(dir: &Path) -> Result<Vec<String>, ExportError> {
    let present = files_under(dir);
    let listed = manifest_files(dir).unwrap_or_default();
    let earlier = listed.is_empty() && is_earlier_run(dir);
    let strangers: Vec<&String> = present
        .iter()
        .filter(|f| *f != MANIFEST && !listed.contains(f) && !carried(f))
        .filter(|f| !(earlier && is_output_name(f)))
        .collect();
    if !strangers.is_empty() {
        let shown: Vec<&str> = strangers.iter().take(5).map(|s| s.as_str()).collect();
        return Err(ExportError::NotARunFolder {
            path: dir.to_owned(),
            strangers: format!(
                "{}{}",
                shown.join(", "),
                if strangers.len() > 5 { ", …" } else { "" }
            ),
        });
    }
    Ok(present
        .into_iter()
        .filter(|f| carried(f) && !listed.contains(f))
        .collect())
}

/// The staged files: `(name, content)`, names relative to the folder.
pub(crate) type Staged<'a> = [(String, Box<dyn FileContent + 'a>)];

/// Replaces the run in `dir` with `files` (see the module's doc).
pub(crate) fn commit_run(files: &Staged, dir: &Path) -> Result<Vec<PathBuf>, ExportError> {
    let (parent, prefix) = siblings(dir);
    std::fs::create_dir_all(&parent).map_err(io(&parent))?;
    // one run at a time beside DIR: the parent folder itself is the lock
    // (nothing is left behind); where a folder cannot be opened as a file
    // (not Linux), runs go unlocked
    let lock = std::fs::File::open(&parent).ok();
    if let Some(l) = &lock {
        l.lock().map_err(io(&parent))?;
    }
    recover(dir)?;
    let keep = if dir.exists() {
        replaceable(dir)?
    } else {
        vec![]
    };
    let stage = parent.join(format!(
        "{prefix}{}-{}.new",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    ));
    let staged = stage_files(files, dir, &stage, &keep);
    if let Err(e) = staged {
        let _ = std::fs::remove_dir_all(&stage);
        return Err(e);
    }
    let old = parent.join(format!("{prefix}{}.old", std::process::id()));
    if dir.exists() {
        std::fs::rename(dir, &old).map_err(io(dir))?;
    }
    std::fs::rename(&stage, dir).map_err(io(dir))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(io(&old))?;
    }
    drop(lock);
    Ok(files.iter().map(|(name, _)| dir.join(name)).collect())
}

/// Writes `files` into `stage`, carries `keep` over from `dir`, and writes
/// the manifest last (a staging folder with one is complete).
fn stage_files(
    files: &Staged,
    dir: &Path,
    stage: &Path,
    keep: &[String],
) -> Result<(), ExportError> {
    use rayon::prelude::*;
    std::fs::create_dir_all(stage).map_err(io(stage))?;
    let written: Result<Vec<String>, ExportError> = files
        .par_iter()
        .map(|(name, content)| {
            let path = stage.join(name);
            if let Some(p) = path.parent() {
                std::fs::create_dir_all(p).map_err(io(p))?;
            }
            crate::write_pieces(&path, &content.pieces()).map_err(io(&path))?;
            Ok(name.clone())
        })
        .collect();
    let mut lines = written?;
    for name in keep {
        let (from, to) = (dir.join(name), stage.join(name));
        if let Some(p) = to.parent() {
            std::fs::create_dir_all(p).map_err(io(p))?;
        }
        std::fs::copy(&from, &to).map_err(io(&from))?;
        lines.push(name.clone());
    }
    lines.sort();
    let manifest = stage.join(MANIFEST);
    std::fs::write(&manifest, lines.join("\n") + "\n").map_err(io(&manifest))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(names: &[(&str, &str)]) -> Vec<(String, Box<dyn FileContent>)> {
        names
            .iter()
            .map(|(n, c)| {
                (
                    n.to_string(),
                    Box::new(c.as_bytes().to_vec()) as Box<dyn FileContent>,
                )
            })
            .collect()
    }

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!(
            "moirecast-run-folder-{}-{name}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_run_replaces_the_last_one_whole() {
        let root = scratch("replace");
        let dir = root.join("out");
        commit_run(&set(&[("mold-top.stl", "a"), ("report.json", "{}")]), &dir).unwrap();
        std::fs::write(dir.join("spec.toml"), "saved").unwrap();
        commit_run(&set(&[("device.stl", "b"), ("report.json", "{}")]), &dir).unwrap();
        let mut left = files_under(&dir);
        left.retain(|f| f != MANIFEST);
        assert_eq!(left, ["device.stl", "report.json", "spec.toml"]);
        let manifest = std::fs::read_to_string(dir.join(MANIFEST)).unwrap();
        assert_eq!(manifest, "device.stl\nreport.json\nspec.toml\n");
        assert_eq!(
            std::fs::read_dir(&root).unwrap().count(),
            1,
            "the folder alone"
        );
    }

    #[test]
    fn a_run_of_an_earlier_moirecast_is_replaced_but_not_other_files() {
        let root = scratch("earlier");
        let dir = root.join("out");
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text) in [
            ("report.json", "{\n  \"moirecast\": \"0.1.0\"\n}"),
            ("device.stl", "x"),
            ("mold-top.step", "x"),
            (".device.stl.9.tmp", "x"),
        ] {
            std::fs::write(dir.join(name), text).unwrap();
        }
        commit_run(&set(&[("device.stl", "b"), ("report.json", "{}")]), &dir).unwrap();
        assert_eq!(files_under(&dir), [MANIFEST, "device.stl", "report.json"]);
        // a note of someone's own in such a folder stops the run
        std::fs::remove_file(dir.join(MANIFEST)).unwrap();
        std::fs::write(dir.join("report.json"), "{\"moirecast\": \"0.1.0\"}").unwrap();
        std::fs::write(dir.join("notes.txt"), "mine").unwrap();
        assert!(commit_run(&set(&[("device.stl", "c")]), &dir).is_err());
        assert!(dir.join("notes.txt").exists());
    }

    #[test]
    fn an_earlier_run_is_named_by_its_files() {
        let dir = scratch("named").join("out");
        assert!(earlier_run(&dir).is_empty());
        commit_run(
            &set(&[("report.json", "{}"), ("device.stl", "solid")]),
            &dir,
        )
        .unwrap();
        std::fs::write(dir.join("spec.toml"), "saved").unwrap();
        // the carried spec is not the run's
        assert_eq!(earlier_run(&dir), ["device.stl", "report.json"]);
        std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
    }

    #[test]
    fn a_folder_of_other_files_is_refused_untouched() {
        let root = scratch("refuse");
        let dir = root.join("mine");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("notes.txt"), "mine").unwrap();
        let e = commit_run(&set(&[("device.stl", "b")]), &dir).unwrap_err();
        assert!(e.to_string().contains("notes.txt"), "{e}");
        assert_eq!(files_under(&dir), ["notes.txt"]);
    }

    #[test]
    fn a_killed_run_is_finished_or_undone_by_the_next() {
        let root = scratch("recover");
        let dir = root.join("out");
        commit_run(&set(&[("a.stl", "old")]), &dir).unwrap();
        let (parent, prefix) = siblings(&dir);
        // killed between the renames: the old run aside, a complete new one staged
        let new = parent.join(format!("{prefix}1-2.new"));
        std::fs::create_dir_all(&new).unwrap();
        std::fs::write(new.join("b.stl"), "new").unwrap();
        std::fs::write(new.join(MANIFEST), "b.stl\n").unwrap();
        std::fs::rename(&dir, parent.join(format!("{prefix}1.old"))).unwrap();
        // and an incomplete staging of another, and an old-style temporary
        std::fs::create_dir_all(parent.join(format!("{prefix}3-4.new"))).unwrap();
        recover(&dir).unwrap();
        assert!(dir.join("b.stl").exists() && !dir.join("a.stl").exists());
        assert_eq!(
            std::fs::read_dir(&root).unwrap().count(),
            1,
            "nothing stray beside it"
        );
        // killed before the staging finished: the old run stays
        std::fs::write(dir.join(".device.stl.77.tmp"), "x").unwrap();
        std::fs::create_dir_all(parent.join(format!("{prefix}5-6.new"))).unwrap();
        recover(&dir).unwrap();
        assert!(dir.join("b.stl").exists() && !dir.join(".device.stl.77.tmp").exists());
        assert_eq!(std::fs::read_dir(&root).unwrap().count(), 1);
    }
}
