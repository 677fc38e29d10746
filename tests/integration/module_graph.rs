//! The layout of `src/`: the arrows between the children of every module
//! folder run one way (no cycle), no library module imports `cli` or
//! `service`, the live path imports no offline tool, and no file grows
//! past [`MAX_LINES`].
//!
//! The graph is read from the source text: every `crate::`, `super::` and
//! `self::` path (grouped `{a, b}` imports too) outside comments and
//! `#[cfg(test)]` modules, resolved to an absolute module path. A file in
//! module `a::b::c` naming `a::d::…` is an arrow `b → d` among the children
//! of `a`. Items re-exported by a folder's `mod.rs` are not followed (an
//! arrow through a re-export is missed, never invented).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Longest file allowed in `src/`.
const MAX_LINES: usize = 700;

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .expect("read src/")
        .map(|e| e.expect("dir entry").path())
        .collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `src/a/b/mod.rs` → `[a, b]`; `src/a/c.rs` → `[a, c]`; `src/lib.rs` → `[]`.
fn module_path(file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src()).expect("under src/");
    let mut parts: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// The text the graph is read from: no line comments, no test modules.
fn code_of(text: &str) -> String {
    let body = text
        .split("\n#[cfg(test)]\nmod ")
        .next()
        .unwrap_or_default();
    body.lines()
        .map(|l| l.split("//").next().unwrap_or_default())
        .collect::<Vec<_>>()
        .join("\n")
}

/// Every path starting with `crate`, `super` or `self`, as its segments
/// (a grouped import gives one path per group member, first segment only).
fn paths_in(code: &str) -> Vec<Vec<String>> {
    let bytes: Vec<char> = code.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let starts_word = i == 0 || !(bytes[i - 1].is_alphanumeric() || bytes[i - 1] == '_');
        let rest: String = bytes[i..bytes.len().min(i + 6)].iter().collect();
        let head = ["crate", "super", "self"]
            .into_iter()
            .find(|h| rest.starts_with(h));
        match head {
            Some(h) if starts_word => {
                let (path, next) = read_path(&bytes, i + h.len(), vec![h.to_string()]);
                out.extend(path);
                i = next;
            }
            _ => i += 1,
        }
    }
    out
}

/// Read `::seg::seg` (and a trailing `::{…}` group) after `prefix`.
fn read_path(chars: &[char], mut i: usize, prefix: Vec<String>) -> (Vec<Vec<String>>, usize) {
    let mut segs = prefix;
    loop {
        if chars.get(i) != Some(&':') || chars.get(i + 1) != Some(&':') {
            return (vec![segs], i);
        }
        i += 2;
        if chars.get(i) == Some(&'{') {
            let (members, end) = group_members(chars, i + 1);
            let paths = members
                .into_iter()
                .map(|m| {
                    let mut p = segs.clone();
                    p.push(m);
                    p
                })
                .collect();
            return (paths, end);
        }
        let start = i;
        while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
            i += 1;
        }
        if i == start {
            return (vec![segs], i);
        }
        segs.push(chars[start..i].iter().collect());
    }
}

/// The first segment of each member of a `{…}` group starting at `i`, and
/// the index after its closing brace.
fn group_members(chars: &[char], mut i: usize) -> (Vec<String>, usize) {
    let mut members = Vec::new();
    let mut depth = 1;
    let mut current = String::new();
    let mut at_member_start = true;
    while i < chars.len() && depth > 0 {
        let c = chars[i];
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 1 => at_member_start = true,
            _ if depth == 1 && at_member_start => {
                if c.is_alphanumeric() || c == '_' {
                    current.push(c);
                } else if !current.is_empty() {
                    members.push(std::mem::take(&mut current));
                    at_member_start = false;
                }
            }
            _ => {}
        }
        i += 1;
    }
    if !current.is_empty() {
        members.push(current);
    }
    (members, i)
}

/// `path` as seen from module `from`, made absolute (`crate` dropped).
fn absolute(from: &[String], path: &[String]) -> Vec<String> {
    let (mut base, mut rest) = match path[0].as_str() {
        "crate" => (Vec::new(), &path[1..]),
        "self" => (from.to_vec(), &path[1..]),
        _ => (from[..from.len().saturating_sub(1)].to_vec(), &path[1..]),
    };
    while rest.first().is_some_and(|s| s == "super") {
        base.pop();
        rest = &rest[1..];
    }
    base.extend(rest.iter().cloned());
    base
}

/// The module tree's children and the arrows among siblings, per parent.
struct Graph {
    children: BTreeMap<Vec<String>, BTreeSet<String>>,
    arrows: BTreeMap<Vec<String>, BTreeSet<(String, String)>>,
}

fn graph() -> Graph {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut children: BTreeMap<Vec<String>, BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let p = module_path(f);
        for i in 0..p.len() {
            children
                .entry(p[..i].to_vec())
                .or_default()
                .insert(p[i].clone());
        }
    }
    let mut arrows: BTreeMap<Vec<String>, BTreeSet<(String, String)>> = BTreeMap::new();
    for f in &files {
        let from = module_path(f);
        let code = code_of(&std::fs::read_to_string(f).expect("read source"));
        for path in paths_in(&code) {
            let to = absolute(&from, &path);
            let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
            if common >= from.len() || common >= to.len() {
                continue;
            }
            let parent = to[..common].to_vec();
            let is_child = children
                .get(&parent)
                .is_some_and(|c| c.contains(&to[common]));
            if is_child && from[common] != to[common] {
                arrows
                    .entry(parent)
                    .or_default()
                    .insert((from[common].clone(), to[common].clone()));
            }
        }
    }
    Graph { children, arrows }
}

/// Strongly connected components of more than one node (Tarjan).
fn cycles(arrows: &BTreeSet<(String, String)>) -> Vec<Vec<String>> {
    let mut next: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (a, b) in arrows {
        next.entry(a).or_default().push(b);
    }
    let nodes: BTreeSet<&str> = arrows
        .iter()
        .flat_map(|(a, b)| [a.as_str(), b.as_str()])
        .collect();
    // Reachability is small here: a node is in a cycle with the nodes it
    // reaches that reach it back.
    let reach = |start: &str| {
        let mut seen = BTreeSet::new();
        let mut stack = vec![start];
        while let Some(v) = stack.pop() {
            for &w in next.get(v).map(Vec::as_slice).unwrap_or_default() {
                if seen.insert(w) {
                    stack.push(w);
                }
            }
        }
        seen
    };
    let reached: BTreeMap<&str, BTreeSet<&str>> = nodes.iter().map(|&n| (n, reach(n))).collect();
    let mut out: Vec<Vec<String>> = Vec::new();
    for &n in &nodes {
        if !reached[n].contains(n) {
            continue;
        }
        let comp: Vec<String> = nodes
            .iter()
            .filter(|&&m| reached[n].contains(m) && reached[m].contains(n))
            .map(|m| m.to_string())
            .collect();
        if !out.contains(&comp) {
            out.push(comp);
        }
    }
    out
}

#[test]
fn no_module_folder_has_an_import_cycle() {
    let g = graph();
    assert!(
        g.children
            .get(&vec!["optim".to_string()])
            .is_some_and(|c| c.contains("scp")),
        "the graph reader found the optimiser's folders"
    );
    let found: Vec<(String, Vec<String>)> = g
        .arrows
        .iter()
        .flat_map(|(parent, arrows)| cycles(arrows).into_iter().map(|c| (parent.join("::"), c)))
        .collect();
    assert!(
        found.is_empty(),
        "import cycles (folder, members): {found:?}"
    );
}

#[test]
fn the_optimiser_folders_import_one_way() {
    let g = graph();
    let optim = &g.arrows[&vec!["optim".to_string()]];
    assert!(cycles(optim).is_empty(), "{optim:?}");
    for below in [
        "task",
        "problem",
        "scp",
        "qp",
        "verify",
        "seeds",
        "infeasible",
    ] {
        assert!(
            !optim.contains(&(below.to_string(), "request".to_string())),
            "optim::{below} imports optim::request"
        );
    }
    // The reader sees a real arrow (the SCP reads the problem).
    assert!(optim.contains(&("scp".to_string(), "problem".to_string())));
}

#[test]
fn the_library_never_imports_its_shells() {
    let g = graph();
    let top = &g.arrows[&Vec::<String>::new()];
    let shells = ["cli", "service", "ros2", "main"];
    let bad: Vec<_> = top
        .iter()
        .filter(|(a, b)| shells.contains(&b.as_str()) && !shells.contains(&a.as_str()))
        .collect();
    assert!(bad.is_empty(), "library modules importing a shell: {bad:?}");
}

/// The modules a request runs through (`/v1/plan`, `/v1/optimize`, `dpmp
/// plan`), as the crate docs group them.
const LIVE_PATH: [&str; 12] = [
    "promp",
    "geometry",
    "robot",
    "scene",
    "perception",
    "net",
    "task_space",
    "plan",
    "optim",
    "error",
    "service",
    "ros2",
];
/// The offline tools (datasets, training, benchmarks, plots, fixtures).
const OFFLINE_TOOLS: [&str; 6] = ["demos", "synth", "train", "bench", "plot", "fixtures"];

#[test]
fn the_live_path_never_imports_an_offline_tool() {
    let g = graph();
    let top = &g.arrows[&Vec::<String>::new()];
    let bad: Vec<_> = top
        .iter()
        .filter(|(a, b)| LIVE_PATH.contains(&a.as_str()) && OFFLINE_TOOLS.contains(&b.as_str()))
        .collect();
    assert!(
        bad.is_empty(),
        "live-path modules importing an offline tool: {bad:?}"
    );
}

#[test]
fn no_source_file_is_longer_than_the_limit() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let lines = std::fs::read_to_string(f).expect("read").lines().count();
            let rel = f.strip_prefix(src()).expect("under src/").to_string_lossy();
            (lines > MAX_LINES).then(|| format!("{rel}: {lines} lines"))
        })
        .collect();
    assert!(long.is_empty(), "over {MAX_LINES} lines: {long:?}");
}

#[test]
fn the_path_reader_resolves_groups_and_supers() {
    let code = "use super::{alpha::A, beta};\nuse crate::x::y;\nlet v = self::z::f();";
    let from: Vec<String> = ["m", "f"].iter().map(|s| s.to_string()).collect();
    let got: Vec<Vec<String>> = paths_in(code).iter().map(|p| absolute(&from, p)).collect();
    let want: Vec<Vec<String>> = [
        vec!["m", "alpha"],
        vec!["m", "beta"],
        vec!["x", "y"],
        vec!["m", "f", "z", "f"],
    ]
    .iter()
    .map(|p| p.iter().map(|s| s.to_string()).collect())
    .collect();
    assert_eq!(got, want);
}
