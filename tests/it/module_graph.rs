//! No import cycle between the library's top-level modules (`src/<module>.rs` or
//! `src/<module>/`): the tree reads like the data flow of docs/architecture.md only while every
//! module depends on the ones below it and none above.
//!
//! The check reads the sources itself (std only): it strips comments, strings and character
//! literals, then follows every path that leaves a module, `crate::x`, `use crate::{x, y::z}`
//! and `super::` climbing to the crate root, recording one file:line for each edge. The binary's
//! modules (`main.rs`, `cli/`) are a crate of their own and are not part of the graph.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// One edge of the graph: module `from` refers to module `to` at `file:line`.
type Edges = BTreeMap<(String, String), String>;

#[derive(Debug, PartialEq)]
enum Token {
    Ident(String),
    Colons,
    Open,
    Close,
    Comma,
    Other,
}

/// The tokens that matter for paths, with their line numbers; comments, string and character
/// literals and lifetimes are dropped (a path inside them is not a dependency).
fn tokens(text: &str) -> Vec<(Token, usize)> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line) = (0, 1);
    let at = |i: usize| chars.get(i).copied().unwrap_or('\0');
    while i < chars.len() {
        let c = chars[i];
        if c == '\n' {
            line += 1;
            i += 1;
        } else if c.is_whitespace() {
            i += 1;
        } else if c == '/' && at(i + 1) == '/' {
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && at(i + 1) == '*' {
            // Block comments nest in Rust.
            let mut depth = 0;
            loop {
                if i >= chars.len() {
                    break;
                } else if chars[i] == '/' && at(i + 1) == '*' {
                    depth += 1;
                    i += 2;
                } else if chars[i] == '*' && at(i + 1) == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    line += usize::from(chars[i] == '\n');
                    i += 1;
                }
            }
        } else if (c == 'r' && (at(i + 1) == '#' || at(i + 1) == '"') && raw_string_hashes(&chars, i + 1).is_some())
            || (c == 'b' && at(i + 1) == 'r' && raw_string_hashes(&chars, i + 2).is_some())
        {
            let start = if c == 'b' { i + 2 } else { i + 1 };
            let hashes = raw_string_hashes(&chars, start).unwrap_or(0);
            i = start + hashes + 1;
            while i < chars.len() && !(chars[i] == '"' && (1..=hashes).all(|k| at(i + k) == '#')) {
                line += usize::from(chars[i] == '\n');
                i += 1;
            }
            i += hashes + 1;
        } else if c == '"' {
            i += 1;
            while i < chars.len() && chars[i] != '"' {
                line += usize::from(chars[i] == '\n');
                i += if chars[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
        } else if c == '\'' {
            // A character literal ('a', '\n', '\u{1F600}') or a lifetime ('a): skip either.
            if at(i + 1) == '\\' {
                i += 2;
                while i < chars.len() && chars[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if at(i + 2) == '\'' {
                i += 3;
            } else {
                i += 1;
                while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                    i += 1;
                }
            }
        } else if c.is_alphabetic() || c == '_' || c == '$' {
            let start = i;
            i += 1;
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            out.push((Token::Ident(chars[start..i].iter().collect()), line));
        } else if c == ':' && at(i + 1) == ':' {
            out.push((Token::Colons, line));
            i += 2;
        } else {
            out.push((
                match c {
                    '{' => Token::Open,
                    '}' => Token::Close,
                    ',' => Token::Comma,
                    _ => Token::Other,
                },
                line,
            ));
            i += 1;
        }
    }
    out
}

/// How many `#` open a raw string whose `#`s or quote start at `i`, if one does.
fn raw_string_hashes(chars: &[char], i: usize) -> Option<usize> {
    let hashes = chars[i.min(chars.len())..].iter().take_while(|&&c| c == '#').count();
    (chars.get(i + hashes) == Some(&'"')).then_some(hashes)
}

/// The module path of a source file under `src/`: `a.rs` and `a/mod.rs` are `[a]`.
fn module_path(relative: &Path) -> Vec<String> {
    let mut parts: Vec<String> = relative.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap_or_default();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts
}

/// The paths a `crate::` or `super::` path starting at `tokens[k]` (the `::` after its
/// prefix) names, each the prefix `base` followed by its identifiers, a `{ .. }` group giving
/// one path per item (nested groups too).
fn paths_after(tokens: &[(Token, usize)], mut k: usize, base: Vec<String>, out: &mut Vec<(Vec<String>, usize)>) {
    let mut path = base;
    let mut line = tokens.get(k).map_or(0, |t| t.1);
    while tokens.get(k).map(|t| &t.0) == Some(&Token::Colons) {
        match tokens.get(k + 1) {
            Some((Token::Ident(name), l)) => {
                path.push(name.clone());
                line = *l;
                k += 2;
            }
            Some((Token::Open, _)) => {
                // Each item of the group starts after its comma (or the brace).
                let mut depth = 0;
                let mut i = k + 1;
                let mut item_start = true;
                while let Some((token, l)) = tokens.get(i) {
                    match token {
                        Token::Open => depth += 1,
                        Token::Close => {
                            depth -= 1;
                            if depth == 0 {
                                break;
                            }
                        }
                        Token::Comma if depth == 1 => item_start = true,
                        Token::Ident(name) if item_start && depth == 1 => {
                            item_start = false;
                            if name != "self" {
                                let mut item = path.clone();
                                item.push(name.clone());
                                // The rest of the item (`::b::{c, d}`) continues from here.
                                let mut more = Vec::new();
                                paths_after(tokens, i + 1, item.clone(), &mut more);
                                if more.is_empty() {
                                    out.push((item, *l));
                                } else {
                                    out.extend(more);
                                }
                            }
                        }
                        _ if depth == 1 => item_start = false,
                        _ => {}
                    }
                    i += 1;
                }
                return;
            }
            _ => break,
        }
    }
    if !path.is_empty() {
        out.push((path, line));
    }
}

/// Every path in `files` (relative to `src/`) that leaves its file's module for another
/// module of the crate, as (the file's module, the path named from the crate root, file:line).
fn references(files: &[(PathBuf, String)]) -> Vec<(Vec<String>, Vec<String>, String)> {
    let mut found = Vec::new();
    for (relative, text) in files {
        let file_path = module_path(relative);
        let tokens = tokens(text);
        // Inline `mod name { ... }` blocks deepen the path `super::` climbs from.
        let mut inline: Vec<(usize, usize)> = Vec::new(); // (brace depth it opened at, path length)
        let mut path = file_path.clone();
        let mut depth = 0;
        let mut i = 0;
        while i < tokens.len() {
            let ident = |k: usize| match tokens.get(k) {
                Some((Token::Ident(name), _)) => Some(name.as_str()),
                _ => None,
            };
            match &tokens[i].0 {
                Token::Open => depth += 1,
                Token::Close => {
                    depth -= 1;
                    if inline.last().is_some_and(|&(d, _)| d == depth) {
                        let (_, len) = inline.pop().unwrap();
                        path.truncate(len);
                    }
                }
                Token::Ident(word) if word == "mod" => {
                    if let (Some(name), Some((Token::Open, _))) = (ident(i + 1), tokens.get(i + 2)) {
                        inline.push((depth, path.len()));
                        path.push(name.to_string());
                    }
                }
                Token::Ident(word) if word == "crate" || word == "super" => {
                    // Climb: `crate` is the root; each `super` one level up from this module.
                    let mut level = if word == "crate" { 0 } else { path.len().saturating_sub(1) };
                    let mut k = i + 1;
                    while word == "super"
                        && tokens.get(k).map(|t| &t.0) == Some(&Token::Colons)
                        && ident(k + 1) == Some("super")
                    {
                        level = level.saturating_sub(1);
                        k += 2;
                    }
                    // A bare `super` or `crate` (`pub(super)`) is a visibility, not a path.
                    if tokens.get(k).map(|t| &t.0) != Some(&Token::Colons) {
                        i = k;
                        continue;
                    }
                    let mut named = Vec::new();
                    paths_after(&tokens, k, path[..level].to_vec(), &mut named);
                    for (to, line) in named {
                        found.push((path.clone(), to, format!("src/{}:{line}", relative.display())));
                    }
                    i = k;
                    continue;
                }
                _ => {}
            }
            i += 1;
        }
    }
    found
}

/// The modules the files define (`a.rs`, `a/mod.rs`), and among them the namespaces: a
/// folder whose `mod.rs` declares modules and nothing else (`formats/`), whose modules stand
/// beside their parent's as if declared there (`formats::tiles` is a module of the root).
fn modules(files: &[(PathBuf, String)]) -> (BTreeSet<Vec<String>>, BTreeSet<Vec<String>>) {
    let all: BTreeSet<Vec<String>> = files.iter().map(|(p, _)| module_path(p)).collect();
    let namespaces = files
        .iter()
        .filter(|(p, text)| {
            p.file_name().is_some_and(|f| f == "mod.rs")
                && tokens(text).split(|(t, _)| *t == Token::Other).all(|item| {
                    let words: Vec<&str> = item
                        .iter()
                        .filter_map(|(t, _)| match t {
                            Token::Ident(w) => Some(w.as_str()),
                            _ => None,
                        })
                        .collect();
                    matches!(words[..], [] | ["mod", _] | ["pub", "mod", _])
                })
        })
        .map(|(p, _)| module_path(p))
        .collect();
    (all, namespaces)
}

/// A module path as the graph's nodes name it: a namespace and the module in it are one name.
fn nodes_of(path: &[String], namespaces: &BTreeSet<Vec<String>>) -> Vec<String> {
    let mut nodes: Vec<String> = Vec::new();
    let mut joined = false;
    for (i, part) in path.iter().enumerate() {
        if joined {
            let last = nodes.last_mut().unwrap();
            last.push_str("::");
            last.push_str(part);
        } else {
            nodes.push(part.clone());
        }
        joined = namespaces.contains(&path[..=i].to_vec());
    }
    nodes
}

/// Every edge between sibling modules, folder by folder: the key `""` holds the root's (the
/// top-level modules, with the namespaces' modules beside them), `"source"` those between
/// `source/`'s modules, `"formats/viewer"` those inside that folder, and so on. A path to an item of a parent module (`crate::source::
/// ImageHeader`) is no edge between siblings.
fn folder_edges(files: &[(PathBuf, String)]) -> BTreeMap<String, Edges> {
    let (modules, namespaces) = modules(files);
    let mut found: BTreeMap<String, Edges> = BTreeMap::new();
    for (from, to, at) in references(files) {
        // The longest prefix of the path that is a module: what the path leaves from.
        let Some(to) = (1..=to.len()).rev().map(|n| &to[..n]).find(|p| modules.contains(*p)) else { continue };
        let (from, to) = (nodes_of(&from, &namespaces), nodes_of(to, &namespaces));
        let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
        if let (Some(a), Some(b)) = (from.get(common), to.get(common)) {
            found
                .entry(from[..common].join("/").replace("::", "/"))
                .or_default()
                .entry((a.clone(), b.clone()))
                .or_insert(at);
        }
    }
    found
}

/// The library's top-level modules, as `src/lib.rs` declares them, with the modules of its
/// namespaces beside them (`formats::tiles`).
fn top_level(files: &[(PathBuf, String)]) -> BTreeSet<String> {
    let (modules, namespaces) = modules(files);
    modules
        .iter()
        .filter(|m| !m.is_empty() && !namespaces.contains(*m))
        .map(|m| nodes_of(m, &namespaces))
        .filter(|n| n.len() == 1)
        .map(|n| n[0].clone())
        .collect()
}

/// The root's edges: between top-level modules.
fn edges(files: &[(PathBuf, String)]) -> Edges {
    folder_edges(files).remove("").unwrap_or_default()
}

/// The strongly connected components of more than one module (Tarjan's algorithm).
fn cycles(nodes: &BTreeSet<String>, edges: &Edges) -> Vec<Vec<String>> {
    struct State<'a> {
        next: BTreeMap<&'a str, Vec<&'a str>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        found: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on_stack.insert(v);
        for w in s.next.get(v).cloned().unwrap_or_default() {
            if !s.index.contains_key(w) {
                visit(s, w);
                let low = s.low[v].min(s.low[w]);
                s.low.insert(v, low);
            } else if s.on_stack.contains(w) {
                let low = s.low[v].min(s.index[w]);
                s.low.insert(v, low);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                component.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                s.found.push(component);
            }
        }
    }
    let mut next: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (from, to) in edges.keys() {
        next.entry(from).or_default().push(to);
    }
    let mut state = State {
        next,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        found: Vec::new(),
    };
    for v in nodes {
        if !state.index.contains_key(v.as_str()) {
            visit(&mut state, v);
        }
    }
    state.found
}

/// What a failure says of each cycle: its modules, and for each edge inside it where it is.
fn describe(cycles: &[Vec<String>], edges: &Edges) -> String {
    let mut text = String::new();
    for component in cycles {
        text += &format!("import cycle between {}:\n", component.join(", "));
        for ((from, to), at) in edges {
            if component.contains(from) && component.contains(to) {
                text += &format!("  {from} -> {to}  ({at})\n");
            }
        }
    }
    text
}

/// Every library source file, relative to `src/`, with its text.
fn library_sources(src: &Path) -> Vec<(PathBuf, String)> {
    fn walk(dir: &Path, src: &Path, out: &mut Vec<(PathBuf, String)>) {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
        entries.sort();
        for path in entries {
            let relative = path.strip_prefix(src).unwrap().to_path_buf();
            if relative == Path::new("main.rs") || relative == Path::new("cli") {
                continue; // the binary's crate
            }
            if path.is_dir() {
                walk(&path, src, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push((relative, std::fs::read_to_string(&path).unwrap()));
            }
        }
    }
    let mut out = Vec::new();
    walk(src, src, &mut out);
    out
}

/// The cycles of every folder's graph, each with its folder.
fn all_cycles(folders: &BTreeMap<String, Edges>) -> String {
    let mut text = String::new();
    for (folder, edges) in folders {
        let nodes: BTreeSet<String> = edges.keys().flat_map(|(a, b)| [a.clone(), b.clone()]).collect();
        let found = cycles(&nodes, edges);
        if !found.is_empty() {
            text += &format!("in src/{folder}:\n{}", describe(&found, edges));
        }
    }
    text
}

#[test]
fn the_library_modules_form_no_import_cycle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files = library_sources(&src);
    let top = top_level(&files);
    assert!(
        top.len() > 10 && top.contains("split") && top.contains("formats::tiles"),
        "the top-level modules: {top:?}"
    );
    let folders = folder_edges(&files);
    let root = &folders[""];
    assert!(root.contains_key(&("split".to_string(), "source".to_string())), "split reads a source: {root:?}");
    assert!(folders["source"].contains_key(&("tiff".to_string(), "jpeg".to_string())), "{:?}", folders["source"]);
    let text = all_cycles(&folders);
    assert!(text.is_empty(), "{text}");
}

fn fixture(files: &[(&str, &str)]) -> (BTreeSet<String>, Edges) {
    let files: Vec<(PathBuf, String)> = files.iter().map(|(p, t)| (PathBuf::from(p), t.to_string())).collect();
    (top_level(&files), edges(&files))
}

#[test]
fn the_check_looks_inside_folders_and_through_namespaces() {
    let files: Vec<(PathBuf, String)> = [
        (
            "lib.rs",
            "pub mod formats;
pub mod low;
",
        ),
        // A namespace: its modules are the root's.
        ("formats/mod.rs", "//! Formats.\npub mod x;\nmod y;\n"),
        (
            "formats/x/mod.rs",
            "mod read;
mod write;
use crate::low::L;
",
        ),
        (
            "formats/x/read.rs",
            "use super::write::W;
",
        ),
        (
            "formats/x/write.rs",
            "use crate::formats::x::read::R;
use super::X;
",
        ),
        (
            "formats/y.rs",
            "use crate::formats::{x::write::W, y::Z};
pub(super) fn f() {}
",
        ),
        (
            "low.rs",
            "pub struct L;
",
        ),
    ]
    .iter()
    .map(|(p, t)| (PathBuf::from(p), t.to_string()))
    .collect();
    assert_eq!(top_level(&files), ["formats::x", "formats::y", "low"].map(String::from).into());
    let folders = folder_edges(&files);
    let listed: Vec<(&str, &str, &str)> =
        folders[""].iter().map(|((f, t), at)| (f.as_str(), t.as_str(), at.as_str())).collect();
    assert_eq!(
        listed,
        [("formats::x", "low", "src/formats/x/mod.rs:3"), ("formats::y", "formats::x", "src/formats/y.rs:1")]
    );
    // read and write use each other; `super::X`, an item of their parent, is no edge.
    let inside: Vec<&(String, String)> = folders["formats/x"].keys().collect();
    assert_eq!(inside, [&("read".to_string(), "write".to_string()), &("write".to_string(), "read".to_string())]);
    let text = all_cycles(&folders);
    assert_eq!(
        layers(&top_level(&files), &folders[""]),
        " 0  low\n 1  formats::x         low\n 2  formats::y         formats::x\n"
    );
    assert!(text.contains("in src/formats/x:") && text.contains("read -> write  (src/formats/x/read.rs:1)"), "{text}");
}

#[test]
fn the_check_finds_a_cycle_through_groups_and_super() {
    let (top, edges) = fixture(&[
        ("lib.rs", "pub mod a;\nmod b;\n#[cfg(test)]\npub mod c;\n"),
        ("a/mod.rs", "mod inner;\npub struct A;\n"),
        // `super::super` from a/inner.rs is the crate root; the group names b.
        ("a/inner.rs", "// crate::c is in a comment\nfn f() {\n    use super::super::{b::X, self as _};\n}\n"),
        ("b.rs", "const S: &str = \"crate::a\";\nfn g(_: &'static str) {}\nuse crate::{\n    c::Y,\n};\n"),
        ("c.rs", "#[cfg(test)]\nmod tests {\n    use super::super::a::Z;\n}\n"),
    ]);
    assert_eq!(top, ["a", "b", "c"].map(String::from).into());
    let listed: Vec<(&str, &str, &str)> =
        edges.iter().map(|((f, t), at)| (f.as_str(), t.as_str(), at.as_str())).collect();
    assert_eq!(listed, [("a", "b", "src/a/inner.rs:3"), ("b", "c", "src/b.rs:4"), ("c", "a", "src/c.rs:3")]);
    let found = cycles(&top, &edges);
    assert_eq!(found, [vec!["a".to_string(), "b".to_string(), "c".to_string()]]);
    let text = describe(&found, &edges);
    assert!(text.contains("import cycle between a, b, c") && text.contains("c -> a  (src/c.rs:3)"), "{text}");
}

#[test]
fn the_check_passes_layers_and_ignores_paths_that_do_not_leave_a_module() {
    let (top, edges) = fixture(&[
        ("lib.rs", "pub mod low;\npub mod high;\n"),
        (
            "low.rs",
            "mod inner { use super::Thing; }\nmacro_rules! m { () => { $crate::high::X } }\nlet r = r#\"crate::high\"#; let c = '\"';\n",
        ),
        ("high.rs", "use crate::low::Thing;\npub(crate) fn f() {}\n"),
    ]);
    let listed: Vec<&(String, String)> = edges.keys().collect();
    assert_eq!(listed, [&("high".to_string(), "low".to_string())]);
    assert!(cycles(&top, &edges).is_empty());
}

/// The modules in layers, each above everything it uses: layer 0 uses no other module, and
/// each module is one layer above the highest it uses. One line per module, with what it uses.
fn layers(top: &BTreeSet<String>, edges: &Edges) -> String {
    let uses = |m: &str| -> Vec<&str> { edges.keys().filter(|(f, _)| f == m).map(|(_, t)| t.as_str()).collect() };
    let mut layer: BTreeMap<&str, usize> = BTreeMap::new();
    // Without a cycle, each pass settles at least one more module; a pass that settles none
    // (an edge to a name that is no module) is a bug of this check, said rather than looped on.
    while layer.len() < top.len() {
        let settled = layer.len();
        for m in top {
            let below: Option<Vec<usize>> = uses(m).iter().map(|u| layer.get(u).copied()).collect();
            if let (false, Some(below)) = (layer.contains_key(m.as_str()), below) {
                layer.insert(m, below.iter().max().map_or(0, |l| l + 1));
            }
        }
        if layer.len() == settled {
            let stuck: Vec<String> = top
                .iter()
                .filter(|m| !layer.contains_key(m.as_str()))
                .map(|m| format!("{m} uses {:?}", uses(m)))
                .collect();
            panic!("no layer for: {}", stuck.join("; "));
        }
    }
    let mut text = String::new();
    for depth in 0..=layer.values().copied().max().unwrap_or(0) {
        for (m, _) in layer.iter().filter(|(_, l)| **l == depth) {
            let line = format!("{depth:>2}  {m:<19}{}", uses(m).join(" "));
            text += line.trim_end();
            text.push('\n');
        }
    }
    text
}

/// An edge to a name that is no module (a namespace taken for one, say) fails the layering
/// at once: the loop that settles layers never spins on it.
#[test]
#[should_panic(expected = "no layer for: a uses [\"formats\"]")]
fn layers_name_a_module_that_uses_no_module() {
    let edges: Edges = [(("a".to_string(), "formats".to_string()), "src/a.rs:1".to_string())].into();
    layers(&["a".to_string()].into(), &edges);
}

/// docs/architecture.md lists the layers as the sources have them; `BLESS=1` rewrites its list.
#[test]
fn the_architecture_doc_lists_the_real_layers() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let src = root.join("src");
    let files = library_sources(&src);
    let (top, edges) = (top_level(&files), edges(&files));
    assert!(cycles(&top, &edges).is_empty(), "the_library_modules_form_no_import_cycle says which");
    let listed = layers(&top, &edges);
    let doc_path = root.join("docs/architecture.md");
    let doc = std::fs::read_to_string(&doc_path).unwrap();
    let (begin, end) = ("<!-- module-layers:begin -->\n```text\n", "```\n<!-- module-layers:end -->");
    let start = doc.find(begin).expect("the module-layers begin marker") + begin.len();
    let stop = doc[start..].find(end).expect("the module-layers end marker") + start;
    if std::env::var_os("BLESS").is_some() {
        std::fs::write(&doc_path, format!("{}{listed}{}", &doc[..start], &doc[stop..])).unwrap();
    } else {
        assert_eq!(&doc[start..stop], listed, "docs/architecture.md's module layers are stale: rerun with BLESS=1");
    }
}

/// The entries of docs/architecture.md's source tree: each folder (`"source/tiff/"`) or
/// top-level line (`""`) with the text that describes its files.
fn tree_entries(doc: &str) -> BTreeMap<String, String> {
    let start = doc.find("```text\nsrc/\n").expect("the source tree") + "```text\nsrc/\n".len();
    let block = &doc[start..start + doc[start..].find("```").expect("the tree's end")];
    let mut entries: BTreeMap<String, String> = BTreeMap::new();
    let mut folders: Vec<String> = Vec::new();
    let mut current = String::new();
    for line in block.lines() {
        let indent = line.len() - line.trim_start().len();
        let first = line.split_whitespace().next().unwrap_or("");
        if indent >= 2 && indent % 2 == 0 && (first.ends_with('/') || first.ends_with(".rs")) {
            folders.truncate(indent / 2 - 1);
            current = match first.strip_suffix('/') {
                Some(folder) => {
                    folders.push(folder.to_string());
                    folders.join("/") + "/"
                }
                None => folders.iter().map(|f| format!("{f}/")).collect(),
            };
        }
        let text = entries.entry(current.clone()).or_default();
        text.push_str(line);
        text.push('\n');
    }
    entries
}

/// Every file of the library and the binary is named in docs/architecture.md's source tree,
/// under its folder: a new file is placed in the data flow when it is added.
#[test]
fn the_architecture_doc_names_every_source_file() {
    fn walk(dir: &Path, src: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, src, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path.strip_prefix(src).unwrap().to_path_buf());
            }
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let entries = tree_entries(&std::fs::read_to_string(root.join("docs/architecture.md")).unwrap());
    let mut files = Vec::new();
    walk(&root.join("src"), &root.join("src"), &mut files);
    let named = |text: &str, word: &str| {
        text.split(|c: char| !(c.is_alphanumeric() || c == '_' || c == '.'))
            .any(|w| w == word || w == format!("{word}.rs"))
    };
    let unnamed: Vec<String> = files
        .iter()
        .filter(|file| {
            let stem = file.file_stem().unwrap().to_string_lossy().into_owned();
            let folder = file.parent().map(|p| p.to_string_lossy().into_owned()).unwrap_or_default();
            let key = if folder.is_empty() { String::new() } else { format!("{folder}/") };
            match entries.get(&key) {
                // A folder's mod.rs is the folder's own entry.
                Some(_) if stem == "mod" => false,
                Some(text) => !named(text, &stem),
                None => true,
            }
        })
        .map(|f| f.display().to_string())
        .collect();
    assert!(unnamed.is_empty(), "docs/architecture.md's source tree does not name {unnamed:?} under its folder");
}
