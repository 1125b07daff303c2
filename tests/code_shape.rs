//! The code stays readable: no function in the crates' and the binary's
//! sources is longer than [`MAX_FUNCTION_LINES`] (a subsystem is split into
//! named stages instead), counted from its `fn` line to its closing brace.

use std::path::{Path, PathBuf};

const MAX_FUNCTION_LINES: usize = 150;

/// `src` with comments, strings and character literals blanked (newlines
/// kept), so that braces are code.
fn code_only(src: &str) -> Vec<u8> {
    let b = src.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    let keep_newlines = |seg: &[u8], out: &mut Vec<u8>| {
        out.extend(seg.iter().filter(|&&c| c == b'\n'));
    };
    while i < b.len() {
        let rest = &b[i..];
        if rest.starts_with(b"//") {
            let end = rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len());
            i += end;
        } else if rest.starts_with(b"/*") {
            let end = rest
                .windows(2)
                .position(|w| w == b"*/")
                .map_or(rest.len(), |e| e + 2);
            keep_newlines(&rest[..end], &mut out);
            i += end;
        } else if (rest.starts_with(b"r\"") || rest.starts_with(b"r#"))
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'))
        {
            let hashes = rest[1..].iter().take_while(|&&c| c == b'#').count();
            let mut close = vec![b'"'];
            close.extend(std::iter::repeat_n(b'#', hashes));
            let start = 2 + hashes;
            let end = rest[start..]
                .windows(close.len())
                .position(|w| w == close.as_slice())
                .map_or(rest.len(), |e| start + e + close.len());
            keep_newlines(&rest[..end], &mut out);
            i += end;
        } else if rest[0] == b'"' {
            let mut j = 1;
            while j < rest.len() && rest[j] != b'"' {
                j += if rest[j] == b'\\' { 2 } else { 1 };
            }
            keep_newlines(&rest[..(j + 1).min(rest.len())], &mut out);
            i += j + 1;
        } else if rest[0] == b'\'' && rest.len() > 2 && (rest[2] == b'\'' || rest[1] == b'\\') {
            // a character literal ('x', '\n', '\u{..}'), not a lifetime
            let end = rest[1..]
                .iter()
                .position(|&c| c == b'\'')
                .map_or(1, |e| e + 2);
            i += end;
        } else {
            out.push(rest[0]);
            i += 1;
        }
    }
    out
}

/// (lines, name, first line) of every function body in `src`.
fn functions(src: &str) -> Vec<(usize, String, usize)> {
    let code = code_only(src);
    let line_of = |at: usize| code[..at].iter().filter(|&&c| c == b'\n').count() + 1;
    let mut found = Vec::new();
    let mut i = 0;
    while let Some(at) = code[i..].windows(3).position(|w| w == b"fn ") {
        let start = i + at;
        i = start + 3;
        if start > 0 && (code[start - 1].is_ascii_alphanumeric() || code[start - 1] == b'_') {
            continue;
        }
        let name: String = code[i..]
            .iter()
            .take_while(|c| c.is_ascii_alphanumeric() || **c == b'_')
            .map(|&c| c as char)
            .collect();
        // the body's opening brace, or a `;` (a declaration without a body)
        let mut j = i;
        let mut parens = 0i32;
        while j < code.len() {
            match code[j] {
                b'(' | b'[' => parens += 1,
                b')' | b']' => parens -= 1,
                b';' if parens <= 0 => break,
                b'{' if parens <= 0 => break,
                _ => {}
            }
            j += 1;
        }
        if j >= code.len() || code[j] == b';' {
            continue;
        }
        let mut depth = 0;
        let mut k = j;
        while k < code.len() {
            match code[k] {
                b'{' => depth += 1,
                b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        break;
                    }
                }
                _ => {}
            }
            k += 1;
        }
        found.push((line_of(k) - line_of(start) + 1, name, line_of(start)));
    }
    found
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn no_function_is_longer_than_the_limit() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    for krate in std::fs::read_dir(root.join("crates")).unwrap() {
        rust_files(&krate.unwrap().path().join("src"), &mut files);
    }
    files.sort();
    let mut longest = (0, String::new());
    let mut over = Vec::new();
    for f in &files {
        for (lines, name, line) in functions(&std::fs::read_to_string(f).unwrap()) {
            let at = format!("{}:{line} {name}", f.strip_prefix(root).unwrap().display());
            if lines > longest.0 {
                longest = (lines, at.clone());
            }
            if lines > MAX_FUNCTION_LINES {
                over.push(format!("{at}: {lines} lines"));
            }
        }
    }
    assert!(files.len() > 50, "found only {} source files", files.len());
    assert!(
        over.is_empty(),
        "functions over {MAX_FUNCTION_LINES} lines (split them into named stages):\n{}",
        over.join("\n")
    );
    println!("longest function: {} lines, {}", longest.0, longest.1);
}

#[test]
fn the_counter_counts() {
    let src = "fn a() {\n    let s = \"}\";\n    // }\n    let c = '}';\n}\nfn b<'x>(v: &'x [u8]) -> usize where u8: Copy {\n  v.len()\n}\n";
    let found = functions(src);
    assert_eq!(
        found,
        vec![(5, "a".to_string(), 1), (3, "b".to_string(), 6)]
    );
}

/// Every `found-<id>` a source file cites is a corpus case by its full
/// 16-digit id, kept in `tests/design-corpus/` (or its `open/` folder), so
/// a reader can replay it.
/// Every Rust file of the workspace: src, tests, benches and the crates.
fn workspace_rust_files(root: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for dir in ["src", "tests", "benches"] {
        rust_files(&root.join(dir), &mut files);
    }
    for krate in std::fs::read_dir(root.join("crates")).unwrap() {
        rust_files(&krate.unwrap().path(), &mut files);
    }
    files
}

/// Every `METHOD §N` the code and the docs cite is a section heading of
/// docs/method.md, and no document links outside the repository for it.
#[test]
fn method_citations_resolve() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let method = std::fs::read_to_string(root.join("docs/method.md")).unwrap();
    let headings: Vec<&str> = method.lines().filter(|l| l.starts_with('#')).collect();
    let mut files = workspace_rust_files(root);
    files.extend(["README.md", "ARCHITECTURE.md"].map(|f| root.join(f)));
    for doc in std::fs::read_dir(root.join("docs")).unwrap() {
        let path = doc.unwrap().path();
        if path.extension().is_some_and(|e| e == "md") {
            files.push(path);
        }
    }
    let (mut cited, mut unresolved) = (0, Vec::new());
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let file = f.strip_prefix(root).unwrap().display().to_string();
        // (built from parts, so that this file does not match itself)
        if text.contains(&["shared", "design", "METHOD"].join("/")) {
            unresolved.push(format!("{file}: links to METHOD.md outside the repository"));
        }
        for (at, _) in text.match_indices("METHOD §") {
            let rest = &text[at + "METHOD §".len()..];
            let number: String = rest
                .chars()
                .take_while(|c| c.is_ascii_digit() || *c == '.')
                .collect();
            let number = number.trim_end_matches('.');
            if number.is_empty() {
                continue; // prose: `METHOD §N`
            }
            cited += 1;
            let heading = format!("§{number} ");
            if !headings
                .iter()
                .any(|h| h.trim_start_matches('#').trim_start().starts_with(&heading))
            {
                unresolved.push(format!("{file}: METHOD §{number}"));
            }
        }
    }
    assert!(cited > 50, "found only {cited} citations");
    assert!(
        unresolved.is_empty(),
        "citations with no section in docs/method.md:\n{}",
        unresolved.join("\n")
    );
}

#[test]
fn cited_corpus_cases_exist() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = workspace_rust_files(root);
    let corpus = root.join("tests/design-corpus");
    let (mut cited, mut missing) = (0, Vec::new());
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        for (at, _) in text.match_indices("found-") {
            let id: String = text[at + 6..]
                .chars()
                .take_while(char::is_ascii_hexdigit)
                .collect();
            if id.is_empty() {
                continue; // prose, or a pattern such as `found-{:016x}`
            }
            cited += 1;
            let name = format!("found-{id}.toml");
            let kept = corpus.join(&name).exists() || corpus.join("open").join(&name).exists();
            if id.len() != 16 || !kept {
                let file = f.strip_prefix(root).unwrap().display();
                missing.push(format!("{file}: found-{id}"));
            }
        }
    }
    assert!(cited > 50, "found only {cited} citations");
    assert!(
        missing.is_empty(),
        "cited corpus cases that are not 16-digit files in tests/design-corpus:\n{}",
        missing.join("\n")
    );
}

/// `docs/checks.md` is what the registry of checks says;
/// `MOIRECAST_BLESS=1` rewrites it.
#[test]
fn docs_checks_md_is_current() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/checks.md");
    let want = moirecast_kernel::checks::markdown();
    if std::env::var_os("MOIRECAST_BLESS").is_some() {
        std::fs::write(path, &want).unwrap();
    }
    let have = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        have == want,
        "docs/checks.md is stale: run `MOIRECAST_BLESS=1 cargo test --test code_shape`"
    );
}
