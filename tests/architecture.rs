//! The house rules of `src/`, checked from the source text: the module graph runs one way,
//! `unsafe` stays in the kernel-facing modules, files stay readable, and the tests need
//! nothing outside the repository.
//!
//! The floors are written once, here, and must match the table under "## Floors" in
//! `ARCHITECTURE.md` (a test below compares them). A module may import from its own floor
//! and the floors below; an import that reaches up a floor fails, with the file and the path
//! that does it. Same-floor imports are allowed but may not form a circle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The floors, lowest first: shared vocabulary at the bottom, the command line at the top.
const FLOORS: &[&[&str]] = &[
    &["decimal", "plot", "rng", "sys", "term", "vocab", "words"],
    &["geometry"],
    &["gcode"],
    &["preprocess"],
    &["buffer"],
    &["fine", "servo"],
    &[
        "gap", "inputs", "output", "parport", "record", "sim", "trace",
    ],
    &["config"],
    &[
        "check",
        "checkpoint",
        "find",
        "machine",
        "plan",
        "report",
        "runtime",
    ],
    &["daemon"],
    &["cli"],
];

/// Imports allowed to run up a floor, as (importing module, imported module). Each one must
/// be explained in ARCHITECTURE.md; there are none.
const ALLOWED_UPWARD: &[(&str, &str)] = &[];

/// The modules allowed `unsafe` (they call the kernel), as files under `src/`.
const UNSAFE_FILES: &[&str] = &[
    "sys/clock.rs",
    "sys/group.rs",
    "sys/limits.rs",
    "sys/rt.rs",
    "parport/ioctl.rs",
];

/// Longest file under `src/`, its tests aside.
const MAX_LINES: usize = 700;
/// Longest function under `src/`, tests aside: past it a function does several things.
const MAX_FN_LINES: usize = 120;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// `src/`-relative path with `/` separators.
fn rel(path: &Path) -> String {
    path.strip_prefix(root().join("src"))
        .unwrap()
        .to_string_lossy()
        .replace('\\', "/")
}

/// The top-level module a file belongs to (`runtime/consumer.rs` → `runtime`); `None` for
/// the crate roots.
fn module_of(rel: &str) -> Option<&str> {
    match rel {
        "lib.rs" | "main.rs" => None,
        _ => Some(rel.split('/').next().unwrap().trim_end_matches(".rs")),
    }
}

fn floor_of(module: &str) -> Option<usize> {
    FLOORS.iter().position(|f| f.contains(&module))
}

/// The source with comments, string literals and char literals blanked out (newlines kept,
/// so line numbers still count), so that paths are only found in code.
fn code_only(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    while i < chars.len() {
        let c = chars[i];
        let next = chars.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < chars.len() && chars[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < chars.len() {
                if chars[i] == '/' && chars.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if chars[i] == '*' && chars.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(chars[i]));
                    i += 1;
                }
            }
        } else if c == 'r' && matches!(next, Some('"') | Some('#')) && !ident_char_before(&chars, i)
        {
            // Raw string r"…" or r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while chars.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if chars.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            j += 1;
            loop {
                match chars.get(j) {
                    None => break,
                    Some('"') if (1..=hashes).all(|k| chars.get(j + k) == Some(&'#')) => {
                        j += 1 + hashes;
                        break;
                    }
                    Some(_) => j += 1,
                }
            }
            for &ch in &chars[i..j.min(chars.len())] {
                out.push(blank(ch));
            }
            i = j;
        } else if c == '"' {
            out.push(' ');
            i += 1;
            while i < chars.len() && chars[i] != '"' {
                if chars[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < chars.len() {
                    out.push(blank(chars[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c == '\'' {
            // A char literal ('x', '\n', '\u{..}'), or a lifetime ('a), which stays.
            let close = if next == Some('\\') {
                (i + 2..chars.len().min(i + 12)).find(|&k| chars[k] == '\'')
            } else if chars.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            match close {
                Some(end) => {
                    for _ in i..=end {
                        out.push(' ');
                    }
                    i = end + 1;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

fn ident_char_before(chars: &[char], i: usize) -> bool {
    i > 0 && (chars[i - 1].is_alphanumeric() || chars[i - 1] == '_')
}

/// Every top-level module named by a `crate::` path in `code` (in `use` lines, groups
/// `crate::{a, b::c}` included, and inline paths), with the line it stands on.
fn crate_paths(code: &str) -> Vec<(String, usize)> {
    let mut found = Vec::new();
    let bytes = code.as_bytes();
    let mut from = 0;
    while let Some(pos) = code[from..].find("crate::") {
        let at = from + pos;
        from = at + "crate::".len();
        if at > 0 && (bytes[at - 1].is_ascii_alphanumeric() || bytes[at - 1] == b'_') {
            continue; // `my_crate::`, not `crate::`
        }
        let line = code[..at].matches('\n').count() + 1;
        let rest = &code[from..];
        if let Some(group) = rest.strip_prefix('{') {
            // Top-level names of the group, at brace depth 0.
            let mut depth = 0;
            let mut name = String::new();
            let mut expect_name = true;
            for ch in group.chars() {
                match ch {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => expect_name = true,
                    c if depth == 0 && expect_name && (c.is_alphanumeric() || c == '_') => {
                        name.push(c)
                    }
                    _ => {
                        if !name.is_empty() {
                            found.push((std::mem::take(&mut name), line));
                        }
                        if depth == 0 && !ch.is_whitespace() {
                            expect_name = false;
                        }
                    }
                }
            }
            if !name.is_empty() {
                found.push((name, line));
            }
        } else {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                found.push((name, line));
            }
        }
    }
    found
}

/// The lines of a file before its unit tests: a `#[cfg(test)]` line followed by a `mod`
/// declaration (inline or a `tests.rs` beside it).
fn lines_before_tests(text: &str) -> usize {
    let lines: Vec<&str> = text.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        if line.trim() == "#[cfg(test)]"
            && lines
                .get(i + 1)
                .is_some_and(|next| next.trim_start().starts_with("mod ") || next.contains(" mod "))
        {
            return i;
        }
    }
    lines.len()
}

/// Imports between top-level modules: (from, to) → the first place that does it.
fn module_imports() -> BTreeMap<(String, String), String> {
    let mut edges = BTreeMap::new();
    for path in rust_files(&root().join("src")) {
        let rel = rel(&path);
        let Some(module) = module_of(&rel) else {
            continue;
        };
        let code = code_only(&std::fs::read_to_string(&path).unwrap());
        for (target, line) in crate_paths(&code) {
            if target == module || target == "self" || target == "super" {
                continue;
            }
            edges
                .entry((module.to_string(), target.clone()))
                .or_insert_with(|| format!("src/{rel}:{line}: crate::{target}"));
        }
    }
    edges
}

#[test]
fn no_module_imports_from_a_floor_above_it() {
    let mut violations = Vec::new();
    for ((from, to), place) in module_imports() {
        let (Some(f), Some(t)) = (floor_of(&from), floor_of(&to)) else {
            violations.push(format!(
                "{place}: `{from}` or `{to}` has no floor in tests/architecture.rs"
            ));
            continue;
        };
        if t > f && !ALLOWED_UPWARD.contains(&(from.as_str(), to.as_str())) {
            violations.push(format!(
                "{place}: `{from}` (floor {f}) imports `{to}` (floor {t}), a floor above it"
            ));
        }
    }
    assert!(
        violations.is_empty(),
        "imports that run up a floor:\n  {}",
        violations.join("\n  ")
    );
}

#[test]
fn the_module_graph_has_no_circle() {
    let edges = module_imports();
    let mut graph: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    for (from, to) in edges.keys() {
        graph.entry(from).or_default().insert(to);
    }
    // Depth-first search, reporting the first circle found with the import that closes it.
    fn visit<'a>(
        node: &'a str,
        graph: &BTreeMap<&'a str, BTreeSet<&'a str>>,
        stack: &mut Vec<&'a str>,
        done: &mut BTreeSet<&'a str>,
    ) -> Option<Vec<&'a str>> {
        if let Some(at) = stack.iter().position(|n| *n == node) {
            let mut circle = stack[at..].to_vec();
            circle.push(node);
            return Some(circle);
        }
        if !done.insert(node) {
            return None;
        }
        stack.push(node);
        for next in graph.get(node).into_iter().flatten() {
            if let Some(circle) = visit(next, graph, stack, done) {
                return Some(circle);
            }
        }
        stack.pop();
        None
    }
    let mut done = BTreeSet::new();
    for node in graph.keys() {
        if let Some(circle) = visit(node, &graph, &mut Vec::new(), &mut done) {
            let places: Vec<&String> = circle
                .windows(2)
                .map(|w| &edges[&(w[0].to_string(), w[1].to_string())])
                .collect();
            panic!(
                "import circle {}:\n  {}",
                circle.join(" -> "),
                places
                    .iter()
                    .map(|s| s.as_str())
                    .collect::<Vec<_>>()
                    .join("\n  ")
            );
        }
    }
}

#[test]
fn every_module_of_the_crate_has_a_floor_and_every_floor_a_module() {
    let lib = std::fs::read_to_string(root().join("src/lib.rs")).unwrap();
    let declared: BTreeSet<String> = lib
        .lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod "))
        .map(|m| m.trim_end_matches(';').to_string())
        .collect();
    let floored: BTreeSet<String> = FLOORS
        .iter()
        .flat_map(|f| f.iter().map(|m| m.to_string()))
        .collect();
    assert_eq!(declared, floored, "src/lib.rs modules vs FLOORS");
}

#[test]
fn architecture_md_lists_the_same_floors() {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let section = text
        .split("\n## Floors")
        .nth(1)
        .expect("ARCHITECTURE.md has a `## Floors` section");
    let section = section.split("\n## ").next().unwrap();
    // Table rows `| N | `a`, `b` | … |`.
    let mut documented: BTreeMap<usize, Vec<String>> = BTreeMap::new();
    for line in section.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 3 {
            continue;
        }
        let Ok(floor) = cells[1].parse::<usize>() else {
            continue;
        };
        let modules = cells[2]
            .split('`')
            .skip(1)
            .step_by(2)
            .map(str::to_string)
            .collect();
        documented.insert(floor, modules);
    }
    let expected: BTreeMap<usize, Vec<String>> = FLOORS
        .iter()
        .enumerate()
        .map(|(i, f)| (i, f.iter().map(|m| m.to_string()).collect()))
        .collect();
    assert_eq!(
        documented, expected,
        "the floors table of ARCHITECTURE.md differs from tests/architecture.rs"
    );
}

#[test]
fn unsafe_code_is_denied_except_in_the_kernel_facing_modules() {
    let lib = std::fs::read_to_string(root().join("src/lib.rs")).unwrap();
    assert!(
        lib.contains("#![deny(unsafe_code)]"),
        "src/lib.rs must deny unsafe_code"
    );
    let mut problems = Vec::new();
    let mut allowed_files = BTreeSet::new();
    for path in rust_files(&root().join("src")) {
        let rel = rel(&path);
        let text = std::fs::read_to_string(&path).unwrap();
        let code = code_only(&text);
        let lines: Vec<&str> = code.lines().collect();
        let text_lines: Vec<&str> = text.lines().collect();
        for (i, line) in lines.iter().enumerate() {
            if line.contains("allow(unsafe_code)") {
                // `#[allow(unsafe_code)]` on a `mod NAME;` line: the file it names.
                let module = lines[i + 1..]
                    .iter()
                    .find_map(|l| {
                        let l = l.trim();
                        l.strip_prefix("pub mod ")
                            .or_else(|| l.strip_prefix("mod "))
                            .map(|m| m.trim_end_matches(';').to_string())
                    })
                    .unwrap_or_default();
                let dir = Path::new(&rel)
                    .parent()
                    .unwrap()
                    .to_string_lossy()
                    .to_string();
                allowed_files.insert(if dir.is_empty() {
                    format!("{module}.rs")
                } else {
                    format!("{dir}/{module}.rs")
                });
            }
            let has_unsafe = line
                .split(|c: char| !c.is_alphanumeric() && c != '_')
                .any(|w| w == "unsafe");
            if has_unsafe {
                if !UNSAFE_FILES.contains(&rel.as_str()) {
                    problems.push(format!(
                        "src/{rel}:{}: `unsafe` outside the kernel-facing modules",
                        i + 1
                    ));
                }
                // The comment right above (possibly over several lines) starts with SAFETY.
                let above = text_lines[..i]
                    .iter()
                    .rev()
                    .take_while(|l| l.trim_start().starts_with("//"))
                    .last();
                if !above.is_some_and(|l| l.trim_start().starts_with("// SAFETY:")) {
                    problems.push(format!(
                        "src/{rel}:{}: `unsafe` without a `// SAFETY:` comment",
                        i + 1
                    ));
                }
            }
        }
    }
    let expected: BTreeSet<String> = UNSAFE_FILES.iter().map(|s| s.to_string()).collect();
    assert_eq!(
        allowed_files, expected,
        "modules with #[allow(unsafe_code)]"
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn no_file_under_src_is_longer_than_the_limit_tests_aside() {
    let mut long = Vec::new();
    for path in rust_files(&root().join("src")) {
        let rel = rel(&path);
        if rel.ends_with("/tests.rs") {
            continue;
        }
        let n = lines_before_tests(&std::fs::read_to_string(&path).unwrap());
        if n > MAX_LINES {
            long.push(format!("src/{rel}: {n} lines"));
        }
    }
    assert!(
        long.is_empty(),
        "files over {MAX_LINES} lines:\n  {}",
        long.join("\n  ")
    );
}

/// The functions of `text` (tests aside) as (name, first line, lines): a `fn` line and the
/// line that closes it at the same indentation.
fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let code = code_only(text);
    let lines: Vec<&str> = code.lines().take(lines_before_tests(text)).collect();
    let mut found = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let trimmed = line.trim_start();
        let indent = line.len() - trimmed.len();
        let head = trimmed
            .trim_start_matches("pub(crate) ")
            .trim_start_matches("pub(super) ")
            .trim_start_matches("pub ")
            .trim_start_matches("const ")
            .trim_start_matches("async ")
            .trim_start_matches("unsafe ");
        let Some(rest) = head.strip_prefix("fn ") else {
            continue;
        };
        let name: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        // A declaration without a body (a trait's) ends on its own line.
        let closing = format!("{}}}", " ".repeat(indent));
        if let Some(end) = lines[i..].iter().position(|l| {
            l.trim_end() == closing
                || (l.trim_end().ends_with(';') && !l.contains('{') && *l == lines[i])
        }) {
            found.push((name, i + 1, end + 1));
        }
    }
    found
}

#[test]
fn no_function_under_src_is_longer_than_the_limit_tests_aside() {
    let mut long = Vec::new();
    for path in rust_files(&root().join("src")) {
        let rel = rel(&path);
        if rel.ends_with("/tests.rs") {
            continue;
        }
        for (name, line, n) in functions(&std::fs::read_to_string(&path).unwrap()) {
            if n > MAX_FN_LINES {
                long.push(format!("src/{rel}:{line}: fn {name}: {n} lines"));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over {MAX_FN_LINES} lines:\n  {}",
        long.join("\n  ")
    );
}

/// `src/lib.rs` lists the modules floor by floor (`// Floor N:` comments): the same floors
/// as the table here (and so as ARCHITECTURE.md's).
#[test]
fn lib_rs_lists_the_same_floors() {
    let text = std::fs::read_to_string(root().join("src/lib.rs")).unwrap();
    let mut floor: Option<usize> = None;
    let mut listed: Vec<BTreeSet<String>> = vec![BTreeSet::new(); FLOORS.len()];
    for line in text.lines() {
        if let Some(rest) = line.trim().strip_prefix("// Floor ") {
            let n: String = rest.chars().take_while(char::is_ascii_digit).collect();
            floor = n.parse().ok();
        } else if let Some(module) = line
            .trim()
            .strip_prefix("pub mod ")
            .and_then(|m| m.strip_suffix(';'))
        {
            let f =
                floor.unwrap_or_else(|| panic!("src/lib.rs: `{module}` under no floor comment"));
            assert!(f < FLOORS.len(), "src/lib.rs: floor {f} does not exist");
            listed[f].insert(module.to_string());
        }
    }
    let table: Vec<BTreeSet<String>> = FLOORS
        .iter()
        .map(|f| f.iter().map(|m| m.to_string()).collect())
        .collect();
    for (n, (lib, want)) in listed.iter().zip(&table).enumerate() {
        assert_eq!(lib, want, "src/lib.rs floor {n}");
    }
}

#[test]
fn the_tick_period_is_converted_only_by_tick_period() {
    let mut by_hand = Vec::new();
    for path in rust_files(&root().join("src")) {
        let rel = rel(&path);
        if rel == "vocab.rs" {
            continue;
        }
        let code = code_only(&std::fs::read_to_string(&path).unwrap());
        for (i, line) in code.lines().enumerate() {
            if line.contains("tick_us as") || line.contains("tick_us *") {
                by_hand.push(format!("src/{rel}:{}: {}", i + 1, line.trim()));
            }
        }
    }
    assert!(
        by_hand.is_empty(),
        "tick conversions outside vocab::TickPeriod:\n  {}",
        by_hand.join("\n  ")
    );
}

#[test]
fn tests_benches_and_sources_read_nothing_outside_the_repository() {
    // The steering repository's folder beside the clone, and this workplace's absolute
    // root; assembled from parts so that this file does not name them itself.
    let sibling = ["..", "shared"].join("/");
    let cases = ["shared", "cases"].join("/");
    let workplace = format!("/{}/", "work");
    let outside_patterns = [sibling, cases, workplace];
    let mut outside = Vec::new();
    for dir in ["src", "tests", "benches", "fuzz"] {
        for path in rust_files(&root().join(dir)) {
            let text = std::fs::read_to_string(&path).unwrap();
            for (i, line) in text.lines().enumerate() {
                if outside_patterns.iter().any(|p| line.contains(p.as_str())) {
                    outside.push(format!("{}:{}: {}", path.display(), i + 1, line.trim()));
                }
            }
        }
    }
    assert!(
        outside.is_empty(),
        "paths outside the repository:\n  {}",
        outside.join("\n  ")
    );
}

#[test]
fn the_path_reader_sees_through_comments_strings_and_groups() {
    let code = code_only(
        "use crate::{a::X, b::{c, d}, e};\n// crate::f\nlet s = \"crate::g\";\nlet c = '\"'; crate::h::y();\n/* crate::i */ my_crate::j; r#\"crate::k\"#;\nfn f<'a>(x: &'a crate::l::T) {}\n",
    );
    let names: Vec<String> = crate_paths(&code).into_iter().map(|(n, _)| n).collect();
    assert_eq!(names, ["a", "b", "e", "h", "l"]);
    assert_eq!(crate_paths(&code)[3].1, 4);
}
