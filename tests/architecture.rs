//! The layering inside the main crate, checked from its source text: what Cargo cannot
//! keep.
//!
//! Cargo keeps the rule between crates, and this test does not repeat it: `rollcam-files`
//! (`files/`: bounded reads, the TIFF codec, the frame types, the capture folder) depends
//! on neither other crate, `rollcam-hw` (`hw/`) only on `rollcam-files`, and only the main
//! crate on both; so no file format reaches a camera or a solver, and the hardware never
//! reaches the reconstruction. Here another crate is a name (`rollcam_hw`, `clap`, `std`),
//! never resolved into its files.
//!
//! Inside the main crate each folder under `src/` is one layer, and dependencies point
//! one way:
//!
//! - each layer of [`LAYERS`] uses only the layers before it;
//! - `model` and `solve` never use `io`, `lab`, `sim`, `analysis`, `perf`, `cli`, the
//!   crates `rollcam_files`, `clap` or `mpi`, and never touch the file system
//!   (`std::fs`, `File`, path queries such as `.exists()`);
//! - `sim` never uses `io`, `analysis`, `perf`, `lab`, `cli`, `rollcam_files`, `clap` or `mpi`;
//! - only the bench (`lab`) and the commands (`cli`) name the hardware crate
//!   `rollcam_hw`; `io` reads capture folders through `rollcam_files`;
//! - no file of the library uses `cli` or `clap` (clap lives in `src/cli` and `src/main.rs`);
//! - the import graph between FILES has no cycle, in each crate (`src/`, `hw/src/`,
//!   `files/src/`).
//!
//! How the graph is built: every file is lexed (comments, doc comments, strings and
//! `#[cfg(test)]` items dropped), then every path it names (`use` trees, grouped or not,
//! and paths written inline in code such as `crate::a::b::f(..)`) is resolved to an
//! absolute module path: `crate`, `super`, `self`, the library's name `rollcam` (in the
//! binary), child modules declared with `mod x;`, and names brought in by a `use`
//! (`use crate::io::{self, ..}` then `io::x`). The edge goes to the file that defines the
//! longest prefix of that path which is a module file (`src/a/b.rs` or `src/a/b/mod.rs`,
//! the crate root for the empty prefix). `mod x;` is not an edge; `pub use x::Y` is.
//! Paths into other crates (`std`, `clap`, ...) are kept for the layer rules only.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::path::Path;

/// Function length and argument-list rules, on the same lexer.
#[path = "architecture/function_size.rs"]
mod function_size;

// ---------------------------------------------------------------------------------------
// Lexing
// ---------------------------------------------------------------------------------------

#[derive(Clone, Debug)]
struct Token {
    text: String,
    ident: bool,
    line: usize,
}

impl Token {
    fn is(&self, s: &str) -> bool {
        self.text == s
    }
}

fn is_ident_start(c: char) -> bool {
    c.is_alphabetic() || c == '_'
}

fn is_ident_char(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Tokens of Rust source: identifiers (keywords included), `::`, single punctuation
/// characters, and one placeholder per string/char/number literal. Comments vanish.
fn lex(src: &str) -> Vec<Token> {
    let c: Vec<char> = src.chars().collect();
    let n = c.len();
    let at = |i: usize| if i < n { c[i] } else { '\0' };
    let mut out = Vec::new();
    let mut i = 0;
    let mut line = 1;
    let push = |out: &mut Vec<Token>, text: String, ident: bool, line: usize| out.push(Token { text, ident, line });
    while i < n {
        let ch = c[i];
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && at(i + 1) == '/' {
            while i < n && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && at(i + 1) == '*' {
            // Block comments nest in Rust.
            let mut depth = 0;
            while i < n {
                if c[i] == '/' && at(i + 1) == '*' {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && at(i + 1) == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if c[i] == '\n' {
                        line += 1;
                    }
                    i += 1;
                }
            }
        } else if ch == '"' {
            let start_line = line;
            i += 1;
            while i < n && c[i] != '"' {
                if c[i] == '\\' {
                    if at(i + 1) == '\n' {
                        line += 1;
                    }
                    i += 2;
                    continue;
                }
                if c[i] == '\n' {
                    line += 1;
                }
                i += 1;
            }
            i += 1;
            push(&mut out, "\"\"".into(), false, start_line);
        } else if ch == '\'' {
            if at(i + 1) == '\\' {
                // Escaped char literal: '\n', '\'', '\u{..}'.
                i += 2;
                while i < n && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
                push(&mut out, "''".into(), false, line);
            } else if at(i + 2) == '\'' {
                i += 3;
                push(&mut out, "''".into(), false, line);
            } else {
                // A lifetime or a label: drop it.
                i += 1;
                while i < n && is_ident_char(c[i]) {
                    i += 1;
                }
            }
        } else if is_ident_start(ch) {
            let start = i;
            while i < n && is_ident_char(c[i]) {
                i += 1;
            }
            let word: String = c[start..i].iter().collect();
            // Raw strings r"..", r#".."#, byte strings b"..", br"..", raw identifiers r#x.
            if (word == "r" || word == "br") && (at(i) == '"' || at(i) == '#') {
                let mut hashes = 0;
                while at(i + hashes) == '#' {
                    hashes += 1;
                }
                if at(i + hashes) == '"' {
                    let start_line = line;
                    i += hashes + 1;
                    loop {
                        if i >= n {
                            break;
                        }
                        if c[i] == '"' && (0..hashes).all(|k| at(i + 1 + k) == '#') {
                            i += 1 + hashes;
                            break;
                        }
                        if c[i] == '\n' {
                            line += 1;
                        }
                        i += 1;
                    }
                    push(&mut out, "\"\"".into(), false, start_line);
                    continue;
                }
                if word == "r" && hashes == 1 && is_ident_start(at(i + 1)) {
                    i += 1;
                    let s = i;
                    while i < n && is_ident_char(c[i]) {
                        i += 1;
                    }
                    push(&mut out, c[s..i].iter().collect(), true, line);
                    continue;
                }
            }
            if word == "b" && (at(i) == '"' || at(i) == '\'') {
                // Byte string or byte char: lex the literal on the next round.
                continue;
            }
            push(&mut out, word, true, line);
        } else if ch.is_ascii_digit() {
            while i < n && is_ident_char(c[i]) {
                i += 1;
            }
            push(&mut out, "0".into(), false, line);
        } else if ch == ':' && at(i + 1) == ':' {
            i += 2;
            push(&mut out, "::".into(), false, line);
        } else {
            i += 1;
            push(&mut out, ch.to_string(), false, line);
        }
    }
    out
}

/// Index just past the bracket that closes the one at `open` (`(`, `[` or `{`).
fn skip_balanced(t: &[Token], open: usize) -> usize {
    let mut depth = 0i32;
    let mut i = open;
    while i < t.len() {
        match t[i].text.as_str() {
            "(" | "[" | "{" => depth += 1,
            ")" | "]" | "}" => {
                depth -= 1;
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
        i += 1;
    }
    t.len()
}

/// Drops every item under `#[cfg(test)]` (or `#[cfg(all(test, ..))]`): its other
/// attributes and the item up to its `;` or its closing `}`; everything when the file
/// starts with `#![cfg(test)]`. Also returns the names of the test-only `mod x;`
/// declarations (their files are test code too).
fn strip_cfg_test(t: Vec<Token>) -> (Vec<Token>, Vec<String>) {
    let text: Vec<&str> = t.iter().take(8).map(|k| k.text.as_str()).collect();
    if text == ["#", "!", "[", "cfg", "(", "test", ")", "]"] {
        return (Vec::new(), Vec::new());
    }
    let mut out = Vec::with_capacity(t.len());
    let mut test_mods = Vec::new();
    let mut i = 0;
    while i < t.len() {
        if t[i].is("#") && i + 1 < t.len() && t[i + 1].is("[") {
            let end = skip_balanced(&t, i + 1);
            let inner: Vec<&str> = t[i + 2..end - 1].iter().map(|k| k.text.as_str()).collect();
            let cfg_test = inner == ["cfg", "(", "test", ")"] || inner.starts_with(&["cfg", "(", "all", "(", "test"]);
            if cfg_test {
                let mut j = end;
                // Further attributes of the same item.
                while j + 1 < t.len() && t[j].is("#") && t[j + 1].is("[") {
                    j = skip_balanced(&t, j + 1);
                }
                let item: Vec<&str> = t[j..t.len().min(j + 5)].iter().map(|k| k.text.as_str()).collect();
                let at_mod = if item.first() == Some(&"pub") && item.get(1) == Some(&"(") {
                    4
                } else if item.first() == Some(&"pub") {
                    1
                } else {
                    0
                };
                if item.get(at_mod) == Some(&"mod") && t.get(j + at_mod + 2).is_some_and(|k| k.is(";")) {
                    test_mods.push(t[j + at_mod + 1].text.clone());
                }
                // The item: up to `;` at its own level, or through its first `{ .. }`.
                while j < t.len() {
                    match t[j].text.as_str() {
                        ";" => {
                            j += 1;
                            break;
                        }
                        "{" => {
                            j = skip_balanced(&t, j);
                            break;
                        }
                        "(" | "[" => j = skip_balanced(&t, j),
                        _ => j += 1,
                    }
                }
                i = j;
                continue;
            }
        }
        out.push(t[i].clone());
        i += 1;
    }
    (out, test_mods)
}

// ---------------------------------------------------------------------------------------
// Files, crates and module paths
// ---------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Crate {
    Lib,
    Bin,
    Hw,
    Files,
}

impl Crate {
    /// The crate a file belongs to, and its module path inside that crate.
    fn of(file: &str) -> Option<(Crate, Vec<String>)> {
        let (krate, rel) = if let Some(rel) = file.strip_prefix("hw/src/") {
            (Crate::Hw, rel)
        } else if let Some(rel) = file.strip_prefix("files/src/") {
            (Crate::Files, rel)
        } else if let Some(rel) = file.strip_prefix("src/") {
            let bin = rel == "main.rs" || rel.starts_with("cli/") || rel == "cli.rs" || rel.starts_with("bin/");
            (if bin { Crate::Bin } else { Crate::Lib }, rel)
        } else {
            return None;
        };
        let rel = rel.strip_suffix(".rs")?;
        let mut module: Vec<String> = rel.split('/').map(String::from).collect();
        let last = module.last().map(String::as_str);
        if last == Some("mod") || (module.len() == 1 && matches!(last, Some("lib") | Some("main"))) {
            module.pop();
        }
        Some((krate, module))
    }

    fn base(self) -> &'static str {
        match self {
            Crate::Lib | Crate::Bin => "src/",
            Crate::Hw => "hw/src/",
            Crate::Files => "files/src/",
        }
    }

    fn root(self) -> &'static str {
        match self {
            Crate::Lib => "src/lib.rs",
            Crate::Bin => "src/main.rs",
            Crate::Hw => "hw/src/lib.rs",
            Crate::Files => "files/src/lib.rs",
        }
    }
}

/// What a path names once resolved.
#[derive(Clone, Debug, PartialEq)]
enum Target {
    /// A module path inside one of the workspace's crates.
    Internal(Crate, Vec<String>),
    /// A path into another crate: `std`, `clap`, `ndarray`...
    External(String, Vec<String>),
}

#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Edge {
    from: String,
    to: String,
    line: usize,
    path: String,
}

#[derive(Clone, Debug)]
struct ExternalUse {
    from: String,
    line: usize,
    krate: String,
    rest: Vec<String>,
    path: String,
}

#[derive(Default, Debug)]
struct Graph {
    edges: Vec<Edge>,
    externals: Vec<ExternalUse>,
    /// Method calls that query the file system (`.exists()`...): (file, line, call).
    fs_calls: Vec<(String, usize, String)>,
}

impl Graph {
    fn has_edge(&self, from: &str, to: &str) -> bool {
        self.edges.iter().any(|e| e.from == from && e.to == to)
    }
}

/// Per-file resolution state.
struct FileCtx<'a> {
    file: &'a str,
    krate: Crate,
    files: &'a BTreeSet<String>,
    /// The child modules declared in each module (`mod x;` or `mod x { .. }`).
    children: Children,
    /// (module path, name) -> what a `use` in that module bound the name to.
    aliases: HashMap<(Vec<String>, String), Target>,
}

impl FileCtx<'_> {
    fn resolve(&self, module: &[String], segs: &[String]) -> Option<Target> {
        let first = segs.first()?.as_str();
        let rest = || segs[1..].to_vec();
        match first {
            "crate" => Some(Target::Internal(self.krate, rest())),
            "self" | "super" => {
                let mut m = module.to_vec();
                let mut k = 0;
                while k < segs.len() && (segs[k] == "self" || segs[k] == "super") {
                    if segs[k] == "super" {
                        m.pop()?;
                    }
                    k += 1;
                }
                m.extend(segs[k..].iter().cloned());
                Some(Target::Internal(self.krate, m))
            }
            "rollcam" if self.krate == Crate::Bin => Some(Target::Internal(Crate::Lib, rest())),
            _ => {
                if self.children.get(module).is_some_and(|c| c.contains(first)) {
                    let mut m = module.to_vec();
                    m.extend(segs.iter().cloned());
                    return Some(Target::Internal(self.krate, m));
                }
                if let Some(t) = self.aliases.get(&(module.to_vec(), first.to_string())) {
                    return Some(match t {
                        Target::Internal(k, p) => Target::Internal(*k, p.iter().chain(&segs[1..]).cloned().collect()),
                        Target::External(k, p) => Target::External(k.clone(), p.iter().chain(&segs[1..]).cloned().collect()),
                    });
                }
                Some(Target::External(first.to_string(), rest()))
            }
        }
    }

    /// The file defining the longest prefix of `path` that is a module file.
    fn file_of(&self, krate: Crate, path: &[String]) -> Option<String> {
        for k in (1..=path.len()).rev() {
            let stem = format!("{}{}", krate.base(), path[..k].join("/"));
            for candidate in [format!("{stem}.rs"), format!("{stem}/mod.rs")] {
                if self.files.contains(&candidate) {
                    return Some(candidate);
                }
            }
        }
        Some(krate.root().to_string())
    }

    fn record(&self, graph: &mut Graph, line: usize, segs: &[String], target: Target) {
        let path = segs.join("::");
        match target {
            Target::Internal(krate, p) => {
                if let Some(to) = self.file_of(krate, &p) {
                    if to != self.file {
                        graph.edges.push(Edge { from: self.file.to_string(), to, line, path });
                    }
                }
            }
            Target::External(krate, rest) => {
                graph.externals.push(ExternalUse { from: self.file.to_string(), line, krate, rest, path });
            }
        }
    }
}

/// Module path -> the names of the child modules declared in it.
type Children = HashMap<Vec<String>, BTreeSet<String>>;

/// For each token, the module it sits in (index into the returned table), and the child
/// modules declared in each module.
fn modules(t: &[Token], root: &[String]) -> (Vec<usize>, Vec<Vec<String>>, Children) {
    let mut table = vec![root.to_vec()];
    let mut children = Children::new();
    let mut stack: Vec<(usize, i32)> = vec![(0, 0)];
    let mut depth = 0i32;
    let mut pending: Option<usize> = None;
    let mut at = Vec::with_capacity(t.len());
    for (i, tok) in t.iter().enumerate() {
        at.push(stack.last().unwrap().0);
        match tok.text.as_str() {
            "mod" if i + 2 < t.len() && t[i + 1].ident => {
                let current = table[stack.last().unwrap().0].clone();
                children.entry(current.clone()).or_default().insert(t[i + 1].text.clone());
                if t[i + 2].is("{") {
                    let mut m = current;
                    m.push(t[i + 1].text.clone());
                    table.push(m);
                    pending = Some(table.len() - 1);
                }
            }
            "{" => {
                depth += 1;
                if let Some(m) = pending.take() {
                    stack.push((m, depth));
                }
            }
            "}" => {
                if stack.len() > 1 && stack.last().unwrap().1 == depth {
                    stack.pop();
                }
                depth -= 1;
            }
            _ => {}
        }
    }
    (at, table, children)
}

/// One leaf of a use tree: its full path, the name it binds (None for globs and `_`).
type UseLeaf = (Vec<String>, Option<String>, usize);

/// Parses a use tree starting at `*i`, prefixing every leaf with `prefix`.
fn parse_use_tree(t: &[Token], i: &mut usize, prefix: &[String], out: &mut Vec<UseLeaf>) {
    let mut segs = prefix.to_vec();
    let line = t.get(*i).map_or(0, |k| k.line);
    if t.get(*i).is_some_and(|k| k.is("::")) {
        *i += 1;
    }
    while *i < t.len() {
        let tok = &t[*i];
        if tok.ident && tok.text != "as" {
            segs.push(tok.text.clone());
            *i += 1;
            if t.get(*i).is_some_and(|k| k.is("::")) {
                *i += 1;
                continue;
            }
            break;
        } else if tok.is("{") {
            *i += 1;
            while *i < t.len() && !t[*i].is("}") {
                parse_use_tree(t, i, &segs, out);
                if t.get(*i).is_some_and(|k| k.is(",")) {
                    *i += 1;
                }
            }
            *i += 1;
            return;
        } else if tok.is("*") {
            *i += 1;
            out.push((segs, None, line));
            return;
        } else {
            // Something unexpected: stop at it without consuming (the caller resyncs).
            if segs.len() > prefix.len() {
                break;
            }
            *i += 1;
            return;
        }
    }
    if segs.last().is_some_and(|s| s == "self") {
        segs.pop();
    }
    let mut name = segs.last().cloned();
    if t.get(*i).is_some_and(|k| k.is("as")) {
        name = t.get(*i + 1).map(|k| k.text.clone());
        *i += 2;
    }
    if name.as_deref() == Some("_") {
        name = None;
    }
    if !segs.is_empty() {
        out.push((segs, name, line));
    }
}

/// Index of the `;` that ends the `use` starting at `i` (or the end).
fn end_of_use(t: &[Token], i: usize) -> usize {
    (i..t.len()).find(|&j| t[j].is(";")).unwrap_or(t.len())
}

/// Method calls that query or change the file system through `Path`.
const FS_METHODS: &[&str] = &["exists", "try_exists", "is_file", "is_dir", "read_dir", "canonicalize", "symlink_metadata"];

/// Builds the import graph of `files` (repository-relative path -> source text).
fn build_graph(files: &BTreeMap<String, String>) -> Graph {
    let names: BTreeSet<String> = files.keys().cloned().collect();
    let mut lexed = BTreeMap::new();
    let mut test_only = BTreeSet::new();
    for (file, src) in files {
        let Some((krate, root)) = Crate::of(file) else { continue };
        let (t, test_mods) = strip_cfg_test(lex(src));
        for m in test_mods {
            let stem = format!("{}{}", krate.base(), root.iter().chain([&m]).cloned().collect::<Vec<_>>().join("/"));
            test_only.extend([format!("{stem}.rs"), format!("{stem}/mod.rs")]);
        }
        lexed.insert(file, (krate, root, t));
    }
    let mut graph = Graph::default();
    for (file, (krate, root, t)) in lexed {
        if test_only.contains(file) {
            continue;
        }
        let (at, table, children) = modules(&t, &root);
        let mut ctx = FileCtx { file, krate, files: &names, children, aliases: HashMap::new() };

        // Pass 1: use trees, in order, binding names as they come.
        let mut uses = Vec::new();
        let mut i = 0;
        while i < t.len() {
            if t[i].is("use") && t[i].ident {
                let end = end_of_use(&t, i);
                let module = &table[at[i]];
                let mut leaves = Vec::new();
                let mut j = i + 1;
                while j < end {
                    let before = j;
                    parse_use_tree(&t, &mut j, &[], &mut leaves);
                    if j == before {
                        j += 1;
                    }
                }
                for (segs, name, line) in leaves {
                    if let Some(target) = ctx.resolve(module, &segs) {
                        if let Some(name) = name {
                            ctx.aliases.insert((module.clone(), name), target.clone());
                        }
                        uses.push((line, segs, target));
                    }
                }
                i = end + 1;
            } else {
                i += 1;
            }
        }
        for (line, segs, target) in uses {
            ctx.record(&mut graph, line, &segs, target);
        }

        // Pass 2: paths written inline, outside `use`, `mod` and `pub(in ..)`.
        let mut i = 0;
        while i < t.len() {
            if t[i].is("use") {
                i = end_of_use(&t, i) + 1;
                continue;
            }
            if t[i].is(".") && i + 2 < t.len() && t[i + 1].ident && FS_METHODS.contains(&t[i + 1].text.as_str()) && t[i + 2].is("(") {
                graph.fs_calls.push((file.clone(), t[i + 1].line, format!(".{}()", t[i + 1].text)));
            }
            let starts_path = t[i].ident
                && i + 2 < t.len()
                && t[i + 1].is("::")
                && t[i + 2].ident
                && !(i > 0 && (t[i - 1].is("::") || t[i - 1].is("in") || t[i - 1].is("mod")));
            if !starts_path {
                i += 1;
                continue;
            }
            let mut segs = vec![t[i].text.clone()];
            let mut j = i + 1;
            while j + 1 < t.len() && t[j].is("::") && t[j + 1].ident {
                segs.push(t[j + 1].text.clone());
                j += 2;
            }
            if let Some(target) = ctx.resolve(&table[at[i]], &segs) {
                ctx.record(&mut graph, t[i].line, &segs, target);
            }
            i = j;
        }
    }
    graph.edges.sort();
    graph.edges.dedup_by(|a, b| a.from == b.from && a.to == b.to && a.line == b.line);
    graph
}

// ---------------------------------------------------------------------------------------
// Rules
// ---------------------------------------------------------------------------------------

/// The layer of a file of the main crate: the folder under `src/` (`cli` for
/// `src/main.rs`, `root` for `src/lib.rs`).
fn layer_of(file: &str) -> String {
    match file.strip_prefix("src/") {
        Some("main.rs") => "cli".into(),
        Some("lib.rs") => "root".into(),
        Some(rel) => rel.split('/').next().unwrap().trim_end_matches(".rs").into(),
        None => "other".into(),
    }
}

/// The library's layers, lowest first (`src/lib.rs` documents the same order).
const LAYERS: [&str; 10] = ["model", "solve", "sim", "io", "request", "analysis", "perf", "cluster", "lab", "cli"];

/// Layers (or other crates) the files of `layer` must not use, and whether it must
/// stay off the file system.
fn forbidden(layer: &str) -> (BTreeSet<&'static str>, bool) {
    let mut out = BTreeSet::new();
    let mut no_fs = false;
    if layer != "cli" {
        out.extend(["cli", "clap"]);
    }
    // The hardware crate: the bench and the commands only.
    if layer != "lab" && layer != "cli" {
        out.insert("rollcam_hw");
    }
    // The layers in order: each may use only those before it.
    if let Some(i) = LAYERS.iter().position(|&l| l == layer) {
        out.extend(LAYERS[i + 1..].iter().copied());
    }
    match layer {
        "model" | "solve" => {
            out.extend(["io", "request", "lab", "sim", "analysis", "perf", "cluster", "cli", "rollcam_files", "clap", "mpi"]);
            no_fs = true;
        }
        "sim" => out.extend(["io", "request", "analysis", "perf", "cluster", "lab", "cli", "rollcam_files", "clap", "mpi"]),
        _ => {}
    }
    (out, no_fs)
}

/// Every breach of the layer rules, as `file:line: message`.
fn layer_violations(graph: &Graph) -> Vec<String> {
    let mut out = Vec::new();
    for e in graph.edges.iter().filter(|e| e.from.starts_with("src/")) {
        let (from, to) = (layer_of(&e.from), layer_of(&e.to));
        if from != to && forbidden(&from).0.contains(to.as_str()) {
            out.push(format!("{}:{}: layer `{from}` must not use `{to}`: `{}` -> {}", e.from, e.line, e.path, e.to));
        }
    }
    for x in graph.externals.iter().filter(|x| x.from.starts_with("src/")) {
        let from = layer_of(&x.from);
        let (banned, no_fs) = forbidden(&from);
        if banned.contains(x.krate.as_str()) {
            out.push(format!("{}:{}: layer `{from}` must not use the crate `{}`: `{}`", x.from, x.line, x.krate, x.path));
        } else if no_fs && x.krate == "std" && x.rest.first().is_some_and(|s| s == "fs") {
            out.push(format!("{}:{}: layer `{from}` must not touch the file system: `{}`", x.from, x.line, x.path));
        }
    }
    for (file, line, call) in graph.fs_calls.iter().filter(|(f, _, _)| f.starts_with("src/")) {
        let from = layer_of(file);
        if forbidden(&from).1 {
            out.push(format!("{file}:{line}: layer `{from}` must not touch the file system: `{call}`"));
        }
    }
    out.sort();
    out.dedup();
    out
}

/// Cycles among the files whose path starts with `under`: one shortest cycle through each
/// file of every strongly connected component with more than one file, each written as
/// `a -> b -> .. -> a` followed by the lines that make the edges.
fn cycles(graph: &Graph, under: &str) -> Vec<String> {
    let mut adj: BTreeMap<&str, BTreeMap<&str, &Edge>> = BTreeMap::new();
    for e in &graph.edges {
        if e.from.starts_with(under) && e.to.starts_with(under) {
            adj.entry(&e.from).or_default().entry(&e.to).or_insert(e);
            adj.entry(&e.to).or_default();
        }
    }
    let nodes: Vec<&str> = adj.keys().copied().collect();
    let index: HashMap<&str, usize> = nodes.iter().enumerate().map(|(i, n)| (*n, i)).collect();
    let succ: Vec<Vec<usize>> = nodes.iter().map(|n| adj[n].keys().map(|m| index[m]).collect()).collect();

    // Tarjan's strongly connected components (iterative).
    let n = nodes.len();
    let (mut idx, mut low, mut on) = (vec![usize::MAX; n], vec![0; n], vec![false; n]);
    let (mut stack, mut comp, mut next) = (Vec::new(), vec![usize::MAX; n], 0);
    let mut ncomp = 0;
    for s in 0..n {
        if idx[s] != usize::MAX {
            continue;
        }
        let mut work = vec![(s, 0usize)];
        idx[s] = next;
        low[s] = next;
        next += 1;
        stack.push(s);
        on[s] = true;
        while let Some(&mut (v, ref mut k)) = work.last_mut() {
            if *k < succ[v].len() {
                let w = succ[v][*k];
                *k += 1;
                if idx[w] == usize::MAX {
                    idx[w] = next;
                    low[w] = next;
                    next += 1;
                    stack.push(w);
                    on[w] = true;
                    work.push((w, 0));
                } else if on[w] {
                    low[v] = low[v].min(idx[w]);
                }
            } else {
                work.pop();
                if let Some(&(u, _)) = work.last() {
                    low[u] = low[u].min(low[v]);
                }
                if low[v] == idx[v] {
                    loop {
                        let w = stack.pop().unwrap();
                        on[w] = false;
                        comp[w] = ncomp;
                        if w == v {
                            break;
                        }
                    }
                    ncomp += 1;
                }
            }
        }
    }

    let mut out = BTreeSet::new();
    for c in 0..ncomp {
        let members: Vec<usize> = (0..n).filter(|&v| comp[v] == c).collect();
        if members.len() < 2 {
            continue;
        }
        for &s in &members {
            // Shortest path s -> .. -> s inside the component.
            let mut prev = vec![usize::MAX; n];
            let mut queue = VecDeque::from([s]);
            let mut found = None;
            'bfs: while let Some(v) = queue.pop_front() {
                for &w in &succ[v] {
                    if comp[w] != c {
                        continue;
                    }
                    if w == s {
                        found = Some(v);
                        break 'bfs;
                    }
                    if prev[w] == usize::MAX {
                        prev[w] = v;
                        queue.push_back(w);
                    }
                }
            }
            let Some(mut v) = found else { continue };
            let mut path = vec![s];
            let mut back = vec![v];
            while v != s {
                v = prev[v];
                if v != s {
                    back.push(v);
                }
            }
            path.extend(back.into_iter().rev());
            // Rotate so the cycle starts at its smallest file: the same cycle prints once.
            let min = (0..path.len()).min_by_key(|&k| nodes[path[k]]).unwrap();
            path.rotate_left(min);
            let files: Vec<&str> = path.iter().chain([&path[0]]).map(|&v| nodes[v]).collect();
            let why: Vec<String> = files
                .windows(2)
                .map(|w| {
                    let e = adj[w[0]][w[1]];
                    format!("{}:{} `{}`", e.from, e.line, e.path)
                })
                .collect();
            out.insert(format!("{}  [{}]", files.join(" -> "), why.join("; ")));
        }
    }
    out.into_iter().collect()
}

// ---------------------------------------------------------------------------------------
// The real tree
// ---------------------------------------------------------------------------------------

fn collect(root: &Path, dir: &Path, out: &mut BTreeMap<String, String>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let p = entry.path();
        if p.is_dir() {
            collect(root, &p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            let rel = p.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
            out.insert(rel, std::fs::read_to_string(&p).unwrap());
        }
    }
}

/// The source folders of the workspace's crates (the Python module is one file).
const CRATE_DIRS: [&str; 3] = ["src", "hw/src", "files/src"];

fn real_graph() -> Graph {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = BTreeMap::new();
    for dir in CRATE_DIRS {
        collect(root, &root.join(dir), &mut files);
        assert!(files.keys().any(|f| f.starts_with(dir)), "no source under {}", root.join(dir).display());
    }
    build_graph(&files)
}

#[test]
fn layers_point_one_way() {
    let v = layer_violations(&real_graph());
    assert!(v.is_empty(), "{} import(s) against the layer rules:\n{}", v.len(), v.join("\n"));
}

#[test]
fn no_file_cycles_in_any_crate() {
    let g = real_graph();
    for dir in CRATE_DIRS {
        let c = cycles(&g, &format!("{dir}/"));
        assert!(c.is_empty(), "{} import cycle(s) between files of {dir}/:\n{}", c.len(), c.join("\n"));
    }
}

/// The checker cannot pass by resolving nothing. `ROLLCAM_PRINT_EDGES=1 cargo test --test
/// architecture resolver -- --nocapture` prints every edge it found.
#[test]
fn resolver_sees_the_real_edges() {
    let g = real_graph();
    if std::env::var_os("ROLLCAM_PRINT_EDGES").is_some() {
        for e in &g.edges {
            println!("{}:{} -> {}  `{}`", e.from, e.line, e.to, e.path);
        }
    }
    let in_src = g.edges.iter().filter(|e| e.from.starts_with("src/") && e.to.starts_with("src/")).count();
    assert!(in_src > 100, "only {in_src} edges between files of src/");
    let in_hw = g.edges.iter().filter(|e| e.from.starts_with("hw/src/") && e.to.starts_with("hw/src/")).count();
    assert!(in_hw > 5, "only {in_hw} edges between files of hw/src/");
    // Another crate is a name, not an edge.
    assert!(g.externals.iter().any(|x| x.from == "src/lab/hardware.rs" && x.krate == "rollcam_hw"), "src/lab/hardware.rs names no rollcam_hw");
    for (from, to) in [
        ("src/solve/scene.rs", "src/model/rolling.rs"),
        ("src/model/rolling.rs", "src/model/conv.rs"),
        ("src/io/output.rs", "src/model/capture.rs"),
        ("src/analysis/report.rs", "src/analysis/spectrum.rs"),
        ("src/main.rs", "src/cli/run.rs"),
        ("files/src/capture.rs", "files/src/frame.rs"),
    ] {
        assert!(
            g.has_edge(from, to),
            "expected an edge {from} -> {to}; edges from {from}: {:?}",
            g.edges.iter().filter(|e| e.from == from).map(|e| &e.to).collect::<Vec<_>>()
        );
    }
}

/// The test binaries in a `tests/` folder: a file `x.rs`, or a folder `x/` with a `main.rs`.
fn test_binaries(dir: &Path) -> Vec<String> {
    let mut out: Vec<String> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs") || p.join("main.rs").is_file())
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    out.sort();
    out
}

/// Every test binary links the whole crate (about 40 MB each), so tests live in a few
/// binaries by layer: a new test file is a module of the binary of what it tests.
#[test]
fn tests_build_few_binaries() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (tests, hw) = (test_binaries(&root.join("tests")), test_binaries(&root.join("hw/tests")));
    assert!(tests.len() <= 8, "{} test binaries in tests/: {tests:?}", tests.len());
    assert!(hw.len() <= 2, "{} test binaries in hw/tests/: {hw:?}", hw.len());
}

// ---------------------------------------------------------------------------------------
// The checker on small examples
// ---------------------------------------------------------------------------------------

fn graph_of(files: &[(&str, &str)]) -> Graph {
    build_graph(&files.iter().map(|(p, s)| (p.to_string(), s.to_string())).collect())
}

fn targets(g: &Graph, from: &str) -> BTreeSet<String> {
    g.edges.iter().filter(|e| e.from == from).map(|e| e.to.clone()).collect()
}

fn set(files: &[&str]) -> BTreeSet<String> {
    files.iter().map(|s| s.to_string()).collect()
}

#[test]
fn checker_resolves_every_kind_of_path() {
    let g = graph_of(&[
        ("src/lib.rs", "pub mod a; pub mod m; pub mod s;"),
        ("src/a/mod.rs", "pub mod b; pub mod c; pub mod d; pub use b::B;"),
        ("src/a/b.rs", "use super::c::C;\nuse self::inner::X;\nmod inner { pub struct X; }\npub struct B;"),
        ("src/a/c.rs", "use crate::{m::M, s::{self, T}};\npub fn c() { s::deep::f(); }"),
        ("src/a/d.rs", "pub fn d() -> u32 { crate::m::g() + super::c::h() }"),
        ("src/m.rs", "pub struct M;"),
        ("src/s/mod.rs", "pub mod deep; pub struct T;"),
        ("src/s/deep.rs", "pub fn f() {}"),
        ("src/main.rs", "mod cli;\nfn main() { cli::go::run(); }"),
        ("src/cli/mod.rs", "pub mod go;"),
        ("src/cli/go.rs", "use rollcam::a::b::B;\nuse rollcam_hw::dev::Dev;\npub fn run() { rollcam::s::deep::f(); }"),
        ("hw/src/lib.rs", "pub mod dev;"),
        ("hw/src/dev.rs", "pub struct Dev;"),
    ]);
    // `mod x;` is no edge; `pub use b::B` in a mod.rs is one.
    assert_eq!(targets(&g, "src/lib.rs"), set(&[]));
    assert_eq!(targets(&g, "src/a/mod.rs"), set(&["src/a/b.rs"]));
    // `super` in a/b.rs is module `a`; `self::inner` stays in the file.
    assert_eq!(targets(&g, "src/a/b.rs"), set(&["src/a/c.rs"]));
    // Grouped use with `self`, then a path through the name it bound.
    assert_eq!(targets(&g, "src/a/c.rs"), set(&["src/m.rs", "src/s/mod.rs", "src/s/deep.rs"]));
    // Inline paths in expressions.
    assert_eq!(targets(&g, "src/a/d.rs"), set(&["src/m.rs", "src/a/c.rs"]));
    // The binary: child modules, and the library by its crate name.
    assert_eq!(targets(&g, "src/main.rs"), set(&["src/cli/go.rs"]));
    // Another crate stays a name.
    assert_eq!(targets(&g, "src/cli/go.rs"), set(&["src/a/b.rs", "src/s/deep.rs"]));
    assert!(g.externals.iter().any(|x| x.from == "src/cli/go.rs" && x.krate == "rollcam_hw" && x.path == "rollcam_hw::dev::Dev"));
}

#[test]
fn checker_resolves_super_in_a_mod_rs_to_the_parent() {
    let g = graph_of(&[
        ("src/lib.rs", "pub mod a; pub mod top; pub fn root_fn() {}"),
        ("src/a/mod.rs", "pub mod x; use super::top::T; fn f() { super::root_fn() }"),
        ("src/a/x.rs", "use super::super::top::T;"),
        ("src/top.rs", "pub struct T;"),
    ]);
    assert_eq!(targets(&g, "src/a/mod.rs"), set(&["src/top.rs", "src/lib.rs"]));
    assert_eq!(targets(&g, "src/a/x.rs"), set(&["src/top.rs"]));
}

#[test]
fn checker_ignores_comments_strings_and_test_code() {
    let g = graph_of(&[
        ("src/lib.rs", "pub mod model; pub mod io;"),
        ("src/io/mod.rs", "pub fn w() {}"),
        ("src/model/helpers.rs", "use crate::io::w;"),
        ("src/model/checks.rs", "#![cfg(test)]\nuse crate::io::w;"),
        (
            "src/model/mod.rs",
            r####"
//! Not [`crate::io::w`]: this is a doc comment.
#[cfg(test)]
pub(crate) mod helpers;
mod checks;
/// Nor this: crate::io::w().
/* nor /* nested */ crate::io::w() */
pub fn f() -> &'static str { let _c = '"'; "crate::io::w()" }
pub fn g() -> &'static str { r#"use crate::io::w; "# }
#[cfg(test)]
mod tests {
    use crate::io::w;
    #[test]
    fn t() { w(); std::fs::read("x").unwrap(); }
}
"####,
        ),
    ]);
    assert_eq!(targets(&g, "src/model/mod.rs"), set(&[]));
    assert_eq!(targets(&g, "src/model/helpers.rs"), set(&[]));
    assert_eq!(targets(&g, "src/model/checks.rs"), set(&[]));
    assert!(layer_violations(&g).is_empty(), "{:?}", layer_violations(&g));
}

#[test]
fn checker_detects_a_forbidden_import() {
    let g = graph_of(&[
        ("src/lib.rs", "pub mod model; pub mod io; pub mod sim; pub mod analysis;"),
        ("src/io/mod.rs", "pub struct IoError;"),
        ("src/model/mod.rs", "pub mod op;"),
        ("src/model/op.rs", "use std::fs;\n\nuse crate::io::IoError;\npub fn f(p: &std::path::Path) -> bool { fs::read(p).is_ok() && p.exists() }"),
        ("src/sim/mod.rs", "pub fn s() { let _ = crate::analysis::a(); }"),
        ("src/analysis/mod.rs", "use clap::Parser;\npub fn a() {}"),
    ]);
    let v = layer_violations(&g);
    assert_eq!(
        v,
        vec![
            "src/analysis/mod.rs:1: layer `analysis` must not use the crate `clap`: `clap::Parser`".to_string(),
            "src/model/op.rs:1: layer `model` must not touch the file system: `std::fs`".to_string(),
            "src/model/op.rs:3: layer `model` must not use `io`: `crate::io::IoError` -> src/io/mod.rs".to_string(),
            "src/model/op.rs:4: layer `model` must not touch the file system: `.exists()`".to_string(),
            "src/model/op.rs:4: layer `model` must not touch the file system: `fs::read`".to_string(),
            "src/sim/mod.rs:1: layer `sim` must not use `analysis`: `crate::analysis::a` -> src/analysis/mod.rs".to_string(),
        ]
    );
}

#[test]
fn checker_detects_hardware_outside_the_bench() {
    // The bench part of an experiment belongs to `lab`, which may use `analysis`; a capture
    // folder is read through `rollcam_files`, not the hardware crate.
    let g = graph_of(&[
        ("src/lib.rs", "pub mod analysis; pub mod io; pub mod lab;"),
        ("src/analysis/mod.rs", "pub mod sweep;"),
        (
            "src/analysis/sweep.rs",
            "use rollcam_hw::led::LedController;
pub fn run() {}
pub fn bench() { let _ = rollcam_hw::camera::open(); }",
        ),
        ("src/io/mod.rs", "use rollcam_files::capture::CaptureReader;\nuse rollcam_hw::record::RecordError;"),
        ("src/lab/mod.rs", "pub mod sweep;"),
        (
            "src/lab/sweep.rs",
            "use crate::analysis::sweep::run;
use rollcam_hw::led::LedController;",
        ),
    ]);
    assert_eq!(
        layer_violations(&g),
        vec![
            "src/analysis/sweep.rs:1: layer `analysis` must not use the crate `rollcam_hw`: `rollcam_hw::led::LedController`".to_string(),
            "src/analysis/sweep.rs:3: layer `analysis` must not use the crate `rollcam_hw`: `rollcam_hw::camera::open`".to_string(),
            "src/io/mod.rs:2: layer `io` must not use the crate `rollcam_hw`: `rollcam_hw::record::RecordError`".to_string(),
        ]
    );
}

#[test]
fn checker_detects_a_cycle() {
    // The usual one: a mod.rs re-exports its children, and a child imports the parent.
    let g = graph_of(&[
        ("src/lib.rs", "pub mod io;"),
        ("src/io/mod.rs", "mod a;\nmod b;\npub use a::write;\npub struct IoError;"),
        ("src/io/a.rs", "use super::IoError;\npub fn write() -> Result<(), IoError> { crate::io::b::helper() }"),
        ("src/io/b.rs", "pub fn helper() -> Result<(), crate::io::IoError> { Ok(()) }"),
        ("hw/src/lib.rs", "pub mod x; pub mod y;"),
        ("hw/src/x.rs", "use crate::y::Y; pub struct X;"),
        ("hw/src/y.rs", "use crate::x::X; pub struct Y;"),
    ]);
    assert_eq!(
        cycles(&g, "src/"),
        vec![
            "src/io/a.rs -> src/io/b.rs -> src/io/mod.rs -> src/io/a.rs  [src/io/a.rs:2 `crate::io::b::helper`; src/io/b.rs:1 `crate::io::IoError`; src/io/mod.rs:3 `a::write`]".to_string(),
            "src/io/a.rs -> src/io/mod.rs -> src/io/a.rs  [src/io/a.rs:1 `super::IoError`; src/io/mod.rs:3 `a::write`]".to_string(),
        ]
    );
    assert_eq!(cycles(&g, "hw/src/").len(), 1);
    assert!(cycles(&g, "hw/src/")[0].starts_with("hw/src/x.rs -> hw/src/y.rs -> hw/src/x.rs"));
}

#[test]
fn checker_accepts_a_clean_graph() {
    // The same layer after the fix: the error in its own file, children import it there.
    let g = graph_of(&[
        ("src/lib.rs", "pub mod io; pub mod model; pub mod sim;"),
        ("src/io/mod.rs", "mod a;\nmod error;\npub use a::write;\npub use error::IoError;"),
        ("src/io/error.rs", "pub struct IoError;"),
        ("src/io/a.rs", "use super::error::IoError;\nuse crate::model::M;\npub fn write() -> Result<(), IoError> { Ok(()) }"),
        ("src/model/mod.rs", "pub struct M;"),
        ("src/sim/mod.rs", "use crate::model::M;"),
    ]);
    assert!(g.edges.len() >= 4, "{:?}", g.edges);
    assert!(cycles(&g, "src/").is_empty(), "{:?}", cycles(&g, "src/"));
    assert!(layer_violations(&g).is_empty(), "{:?}", layer_violations(&g));
}

#[test]
fn checker_detects_a_layer_used_against_the_order() {
    // The forward model below the solvers; the simulator below the file formats.
    let g = graph_of(&[
        ("src/lib.rs", "pub mod model; pub mod solve; pub mod sim; pub mod io;"),
        ("src/model/mod.rs", "pub mod op;"),
        ("src/model/op.rs", "use crate::solve::tv::Tv;\npub trait Operator {}"),
        ("src/solve/mod.rs", "pub mod tv;"),
        ("src/solve/tv.rs", "use crate::model::op::Operator;\npub struct Tv;"),
        ("src/sim/mod.rs", "pub mod expose;"),
        ("src/sim/expose.rs", "use crate::model::op::Operator;\npub fn save() { crate::io::write(); }"),
        ("src/io/mod.rs", "pub fn write() {}\npub fn sim() { crate::sim::expose::save(); }"),
    ]);
    let v = layer_violations(&g);
    assert!(v.iter().any(|m| m.starts_with("src/model/op.rs:1: layer `model` must not use `solve`")), "{v:?}");
    assert!(v.iter().any(|m| m.starts_with("src/sim/expose.rs:2: layer `sim` must not use `io`")), "{v:?}");
    assert!(!v.iter().any(|m| m.starts_with("src/solve/") || m.starts_with("src/io/")), "a use down the order was refused: {v:?}");
}
