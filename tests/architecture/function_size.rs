//! Small functions and short argument lists, checked from the source text.
//!
//! - No function of `src/`, `hw/src/`, `files/src/` or `python/src/` is longer than
//!   [`MAX_FUNCTION_LINES`] lines, from the line of its `fn` to the line of its closing
//!   brace, except under `src/solve/optimize/` (the numerical steps stay in one piece
//!   where their doc says why). Nested functions and closures count in the function that
//!   holds them, and a nested `fn` is measured on its own as well.
//! - The whole workspace holds at most [`MAX_ARGUMENT_ALLOWS`]
//!   `#[allow(clippy::too_many_arguments)]`, and none at module level: a long argument
//!   list becomes a parameter struct.
//!
//! Functions are found on the tokens of the layering checker's lexer, so braces inside
//! strings, chars and comments do not count.

use super::{lex, skip_balanced, Token};
use std::path::{Path, PathBuf};

/// The longest function allowed outside `src/solve/optimize/`, in lines.
pub const MAX_FUNCTION_LINES: usize = 150;

/// The most `#[allow(clippy::too_many_arguments)]` the workspace may hold.
pub const MAX_ARGUMENT_ALLOWS: usize = 6;

/// Folders whose functions are measured, relative to the repository root (a folder the
/// workspace does not have is skipped).
const MEASURED: [&str; 4] = ["src", "hw/src", "files/src", "python/src"];

/// Folders left out of the length rule.
const EXEMPT: [&str; 1] = ["src/solve/optimize/"];

/// One function with a body: its name, the line of its `fn` and its length in lines.
#[derive(Debug, PartialEq)]
pub struct FnSpan {
    pub name: String,
    pub line: usize,
    pub lines: usize,
}

/// Every function with a body in `src`, nested ones included, in source order.
pub fn functions(src: &str) -> Vec<FnSpan> {
    let t = lex(src);
    let mut out = Vec::new();
    for i in 0..t.len() {
        // `fn name`: an item or a method; `fn(` is a pointer type, `fn $x` a macro pattern.
        if !(t[i].is("fn") && t.get(i + 1).is_some_and(|n| n.ident)) {
            continue;
        }
        if let Some(open) = body_start(&t, i + 2) {
            let close = skip_balanced(&t, open) - 1;
            let end_line = t.get(close).map_or(t[t.len() - 1].line, |c| c.line);
            out.push(FnSpan { name: t[i + 1].text.clone(), line: t[i].line, lines: end_line - t[i].line + 1 });
        }
    }
    out
}

/// Index of the `{` that opens the body of the function whose signature starts at `i`,
/// or None for a declaration without a body (`fn f();` in a trait or an `extern` block).
/// Brackets in the signature (a destructured argument, an array type `[u8; 4]`) are
/// skipped whole.
fn body_start(t: &[Token], mut i: usize) -> Option<usize> {
    while i < t.len() {
        match t[i].text.as_str() {
            "{" => return Some(i),
            ";" => return None,
            "(" | "[" => i = skip_balanced(t, i),
            _ => i += 1,
        }
    }
    None
}

/// How many `clippy::too_many_arguments` allows `src` holds, and how many of them are
/// inner attributes (`#![allow(..)]`, which would silence a whole module).
pub fn argument_allows(src: &str) -> (usize, usize) {
    let t = lex(src);
    let (mut outer, mut inner) = (0, 0);
    for i in 0..t.len() {
        if !(t[i].is("#") && matches!(t.get(i + 1), Some(b) if b.is("[") || b.is("!"))) {
            continue;
        }
        let bang = t[i + 1].is("!");
        let open = if bang { i + 2 } else { i + 1 };
        if !t.get(open).is_some_and(|b| b.is("[")) || !t.get(open + 1).is_some_and(|a| a.is("allow") || a.is("expect")) {
            continue;
        }
        let end = skip_balanced(t.as_slice(), open);
        let hits = t[open..end].windows(3).filter(|w| w[0].is("clippy") && w[1].is("::") && w[2].is("too_many_arguments")).count();
        if bang {
            inner += hits;
        } else {
            outer += hits;
        }
    }
    (outer, inner)
}

/// Every `.rs` file under `dir`, as (repository-relative path, absolute path), skipping
/// build output and hidden folders.
fn rust_files(root: &Path, dir: &Path, out: &mut Vec<(String, PathBuf)>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let p = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if p.is_dir() {
            if name != "target" && !name.starts_with('.') {
                rust_files(root, &p, out);
            }
        } else if p.extension().is_some_and(|e| e == "rs") {
            let rel = p.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
            out.push((rel, p));
        }
    }
}

fn repository_root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Functions over [`MAX_FUNCTION_LINES`] in the measured folders, as
/// `file:line: name is N lines`, longest first.
fn long_functions() -> Vec<String> {
    let root = repository_root();
    let mut files = Vec::new();
    for dir in MEASURED {
        rust_files(root, &root.join(dir), &mut files);
    }
    assert!(files.iter().any(|(rel, _)| rel == "src/lib.rs"), "source tree not found under {}", root.display());
    let mut long: Vec<(usize, String)> = Vec::new();
    for (rel, path) in files.iter().filter(|(rel, _)| !EXEMPT.iter().any(|e| rel.starts_with(e))) {
        for f in functions(&read(path)).into_iter().filter(|f| f.lines > MAX_FUNCTION_LINES) {
            long.push((f.lines, format!("{rel}:{}: `{}` is {} lines", f.line, f.name, f.lines)));
        }
    }
    long.sort_by(|a, b| b.0.cmp(&a.0).then_with(|| a.1.cmp(&b.1)));
    long.into_iter().map(|(_, m)| m).collect()
}

#[test]
fn no_long_functions() {
    let long = long_functions();
    assert!(long.is_empty(), "{} function(s) over {MAX_FUNCTION_LINES} lines (split them into named steps):\n{}", long.len(), long.join("\n"));
}

#[test]
fn few_long_argument_lists() {
    let root = repository_root();
    let mut files = Vec::new();
    rust_files(root, root, &mut files);
    let mut places = Vec::new();
    let mut inner_places = Vec::new();
    for (rel, path) in &files {
        let (outer, inner) = argument_allows(&read(path));
        if outer > 0 {
            places.push(format!("{rel}: {outer}"));
        }
        if inner > 0 {
            inner_places.push(format!("{rel}: {inner}"));
        }
    }
    assert!(inner_places.is_empty(), "module-level allows of clippy::too_many_arguments:\n{}", inner_places.join("\n"));
    let total: usize = places.iter().map(|p| p.rsplit(' ').next().unwrap().parse::<usize>().unwrap()).sum();
    assert!(
        total <= MAX_ARGUMENT_ALLOWS,
        "{total} allows of clippy::too_many_arguments (at most {MAX_ARGUMENT_ALLOWS}; use a parameter struct):\n{}",
        places.join("\n")
    );
}

#[test]
fn function_scan_skips_strings_comments_and_signatures() {
    let src = r#"
// fn commented() { {
pub fn first(S { a, b }: S, n: [u8; 4]) -> impl Fn(u8) -> u8 {
    let s = "}}} fn fake() {";
    let c = '}';
    /* } nested /* } */ */
    fn inner<'a>(x: &'a str) -> &'a str {
        x
    }
    move |v| v
}
trait T {
    fn declared(&self);
    fn defaulted(&self) -> u8 { 1 }
}
type P = fn(u8) -> u8;
macro_rules! m { ($n:ident) => { fn $n() {} } }
"#;
    let f = functions(src);
    let spans: Vec<(&str, usize, usize)> = f.iter().map(|s| (s.name.as_str(), s.line, s.lines)).collect();
    assert_eq!(spans, vec![("first", 3, 9), ("inner", 7, 3), ("defaulted", 14, 1)]);
}

#[test]
fn allow_count_reads_attributes_not_comments() {
    let src = r##"
// #[allow(clippy::too_many_arguments)]
#[allow(clippy::too_many_arguments)]
fn a() {}
#[allow(dead_code, clippy::too_many_arguments)]
fn b() {}
#[allow(clippy::type_complexity)]
fn c() { let _ = "#[allow(clippy::too_many_arguments)]"; }
mod m {
    #![allow(clippy::too_many_arguments)]
}
"##;
    assert_eq!(argument_allows(src), (2, 1));
}

#[test]
fn the_length_checker_sees_the_real_tree() {
    // It cannot pass by finding nothing: the tree holds hundreds of functions, and the
    // exempt numerical steps are found (and left out) too.
    let root = repository_root();
    let mut files = Vec::new();
    rust_files(root, &root.join("src"), &mut files);
    let all: usize = files.iter().map(|(_, p)| functions(&read(p)).len()).sum();
    assert!(all > 500, "only {all} functions found under src/");
    let prepare = functions(&read(&root.join("src/model/prepare.rs")));
    assert!(prepare.iter().any(|f| f.name == "prepare" && f.lines > 10), "{prepare:?}");
}
