//! The house rules of `src/`, checked from the source text: the module graph runs one way,
//! `unsafe` stays in the kernel-facing modules, files stay readable, and the tests need
//! nothing outside the repository.
//!
//! The floors are written once, here, and must match the table under "## Floors" in
//! `ARCHITECTURE.md` (a test below compares them). A module may import from its own floor
//! and the floors below; an import that reaches up a floor fails, with the file and the path
//! that does it. Same-floor imports are allowed but may not form a circle.

mod source;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use source::{
    code_only, code_without_tests, crate_paths, impl_blocks, inherent_impls, module_paths,
};

/// The floors, lowest first: shared vocabulary at the bottom, the command line at the top.
const FLOORS: &[&[&str]] = &[
    &["decimal", "plot", "rng", "sys", "term", "vocab", "words"],
    &["geometry"],
    &["gcode"],
    &["path"],
    &["preprocess"],
    &["buffer"],
    &["fine", "process", "servo"],
    &[
        "gap", "hal", "inputs", "output", "parport", "record", "sim", "trace",
    ],
    &["config"],
    &[
        "check",
        "checkpoint",
        "machine",
        "plan",
        "report",
        "runtime",
        "technology",
        "touch",
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
    "hal/ffi.rs",
];

/// Longest file under `src/`, its tests aside.
const MAX_LINES: usize = 700;
/// Longest function under `src/`, tests aside: past it a function does several things.
const MAX_FN_LINES: usize = 120;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path) -> Vec<PathBuf> {
    files_ending(dir, &["rs"])
}

/// Every file under `dir` whose extension is one of `extensions`, sorted.
fn files_ending(dir: &Path, extensions: &[&str]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path
                .extension()
                .is_some_and(|e| extensions.iter().any(|x| e == *x))
            {
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

/// Imports between top-level modules: (from, to) → the first place that does it.
fn module_imports() -> BTreeMap<(String, String), String> {
    let mut edges = BTreeMap::new();
    for path in rust_files(&root().join("src")) {
        let rel = rel(&path);
        let Some(module) = module_of(&rel) else {
            continue;
        };
        let code = code_without_tests(&std::fs::read_to_string(&path).unwrap());
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
                "{place}: `{from}` or `{to}` has no floor in tests/it/architecture/"
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
        "the floors table of ARCHITECTURE.md differs from tests/it/architecture/mod.rs"
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

/// Every file counts whole: its inline tests and a `tests.rs` beside it are read as much as
/// the code (a file once measured to its first `#[cfg(test)] mod` let 510 lines escape), and
/// the page's markup, style and script as much as Rust (the page was once 999 lines that no
/// rule counted).
#[test]
fn no_file_under_src_is_longer_than_the_limit() {
    let mut long = Vec::new();
    let sources = files_ending(&root().join("src"), &["rs", "html", "css", "js"]);
    assert!(
        sources.iter().any(|p| p.extension().unwrap() == "js"),
        "the page's script is counted"
    );
    for path in sources {
        let rel = rel(&path);
        let n = std::fs::read_to_string(&path).unwrap().lines().count();
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
    let code = code_without_tests(text);
    let lines: Vec<&str> = code.lines().collect();
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
        if rel == "vocab/tick.rs" || rel == "vocab/tests.rs" {
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
        "tick conversions outside vocab::TickPeriod (vocab/tick.rs):\n  {}",
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

/// Most files a type's inherent `impl` blocks may be spread over: past it the type's methods
/// have left the parts that own their state.
const MAX_IMPL_FILES: usize = 3;

/// Types whose methods are still spread wider, with the number of files they span today: the
/// number may only fall (a type that grows wider fails, one back within the limit must be
/// taken off the list). Each is a debt named in ARCHITECTURE.md, "Debts".
const WIDE_TYPES: &[(&str, usize)] = &[
    // The daemon's control loop: the job's lifecycle (start, jobs), the transports' dispatch,
    // the status and the loop's round (upkeep); the machine's commands decide at the desk.
    ("Core", 5),
];

/// The files each type's inherent `impl` blocks stand in (tests aside).
fn impl_files() -> BTreeMap<String, BTreeSet<String>> {
    let mut files: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for path in rust_files(&root().join("src")) {
        let rel = rel(&path);
        let code = code_without_tests(&std::fs::read_to_string(&path).unwrap());
        for (name, _) in inherent_impls(&code) {
            files.entry(name).or_default().insert(format!("src/{rel}"));
        }
    }
    files
}

#[test]
fn no_type_spreads_its_methods_over_more_than_three_files() {
    let mut wide = Vec::new();
    for (name, files) in impl_files() {
        let allowed = WIDE_TYPES
            .iter()
            .find(|(n, _)| *n == name)
            .map_or(MAX_IMPL_FILES, |(_, n)| *n);
        if files.len() > allowed {
            wide.push(format!(
                "{name}: {} files (at most {allowed}): {}",
                files.len(),
                files.iter().cloned().collect::<Vec<_>>().join(", ")
            ));
        }
    }
    for (name, n) in WIDE_TYPES {
        let now = impl_files().get(*name).map_or(0, BTreeSet::len);
        if now <= MAX_IMPL_FILES {
            wide.push(format!(
                "{name} spans {now} files now: take it off WIDE_TYPES (listed at {n})"
            ));
        }
    }
    assert!(
        wide.is_empty(),
        "types whose impl blocks span too many files:\n  {}",
        wide.join("\n  ")
    );
}

/// Types whose files still call one another round a circle, with the number of files on it
/// today: it may only fall. Each is a debt named in ARCHITECTURE.md, "Debts".
const CALL_CIRCLES: &[(&str, usize)] = &[];

/// For each type whose methods stand in more than one file: which file calls a method that
/// another one defines (`self.name(…)`), as (type, from file, to file) and the methods called.
fn method_calls_across_files() -> BTreeMap<(String, String, String), BTreeSet<String>> {
    let mut defined: BTreeMap<(String, String), BTreeSet<String>> = BTreeMap::new();
    let mut calling: Vec<(String, String, BTreeSet<String>)> = Vec::new();
    for path in rust_files(&root().join("src")) {
        let rel = format!("src/{}", rel(&path));
        let code = code_without_tests(&std::fs::read_to_string(&path).unwrap());
        for block in impl_blocks(&code) {
            for method in block.defines {
                defined
                    .entry((block.name.clone(), method))
                    .or_default()
                    .insert(rel.clone());
            }
            calling.push((block.name, rel.clone(), block.calls));
        }
    }
    let mut edges = BTreeMap::new();
    for (name, from, calls) in calling {
        for method in calls {
            // A name defined in more than one file (two impls of a generic type) says nothing
            // of which one is called.
            let Some(files) = defined.get(&(name.clone(), method.clone())) else {
                continue;
            };
            if files.len() == 1 && !files.contains(&from) {
                let to = files.iter().next().unwrap().clone();
                edges
                    .entry((name.clone(), from.clone(), to))
                    .or_insert_with(BTreeSet::new)
                    .insert(method);
            }
        }
    }
    edges
}

/// The circles of each type's call graph between its files: the files that reach one
/// another both ways, per type.
fn call_circles() -> BTreeMap<String, Vec<BTreeSet<String>>> {
    let mut graphs: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (name, from, to) in method_calls_across_files().into_keys() {
        graphs
            .entry(name)
            .or_default()
            .entry(from)
            .or_default()
            .insert(to);
    }
    let mut circles = BTreeMap::new();
    for (name, graph) in graphs {
        let reach = |start: &String| {
            let mut seen = BTreeSet::new();
            let mut todo = vec![start.clone()];
            while let Some(f) = todo.pop() {
                for g in graph.get(&f).into_iter().flatten() {
                    if seen.insert(g.clone()) {
                        todo.push(g.clone());
                    }
                }
            }
            seen
        };
        let reached: BTreeMap<&String, BTreeSet<String>> =
            graph.keys().map(|f| (f, reach(f))).collect();
        let mut found: Vec<BTreeSet<String>> = Vec::new();
        for (f, r) in &reached {
            if !r.contains(*f) || found.iter().any(|c| c.contains(*f)) {
                continue;
            }
            let circle: BTreeSet<String> = r
                .iter()
                .filter(|g| reached.get(g).is_some_and(|rg| rg.contains(*f)))
                .cloned()
                .collect();
            found.push(circle);
        }
        if !found.is_empty() {
            circles.insert(name, found);
        }
    }
    circles
}

#[test]
fn no_type_calls_round_a_circle_of_its_files() {
    let circles = call_circles();
    let mut wrong = Vec::new();
    for (name, found) in &circles {
        let allowed = CALL_CIRCLES
            .iter()
            .find(|(n, _)| n == name)
            .map_or(0, |(_, n)| *n);
        for circle in found {
            if circle.len() > allowed {
                wrong.push(format!(
                    "{name}: {} files call one another round a circle (at most {allowed}): {}",
                    circle.len(),
                    circle.iter().cloned().collect::<Vec<_>>().join(", ")
                ));
            }
        }
    }
    for (name, n) in CALL_CIRCLES {
        let now = circles
            .get(*name)
            .and_then(|c| c.iter().map(BTreeSet::len).max())
            .unwrap_or(0);
        if now < *n {
            wrong.push(format!(
                "{name}'s circle has {now} files now: lower CALL_CIRCLES (listed at {n})"
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "a type's files call one another round a circle: a method moved to the file that \
         owns its state breaks it\n  {}",
        wrong.join("\n  ")
    );
}

#[test]
fn the_call_reader_finds_methods_called_across_lines() {
    let code = code_only(
        "impl A {\n    fn one(&self) { self.two(); self\n        .three::<u8>(); self.field.four(); }\n    pub(crate) fn five() { Self::six(1) }\n}\nimpl Tr for A { fn seven(&self) { self.eight() } }\n",
    );
    let blocks = impl_blocks(&code);
    assert_eq!(blocks.len(), 1, "a trait's impl is not the type's own");
    assert_eq!(blocks[0].defines, ["one", "five"]);
    let calls: Vec<&String> = blocks[0].calls.iter().collect();
    assert_eq!(calls, ["six", "three", "two"]);
}

/// Floors inside the modules whose children import one another, lowest first, as for the
/// crate's modules. `mod` is the module's own `mod.rs` and what it declares; a child on its
/// floor is one of its rooms and may use what `mod.rs` declares, a child below may not.
const INNER_FLOORS: &[(&str, &[&[&str]])] = &[
    (
        "daemon",
        &[
            &["history", "noise", "notify", "refusal"],
            &["board", "launch", "link", "names", "protocol"],
            &["http"],
            &["mqtt", "opcua"],
            &["desk", "error", "reload", "socket"],
            // The control loop (`Core`, in mod.rs) and the rooms that extend it.
            &[
                "checkpoints",
                "dispatch",
                "jobs",
                "machine",
                "mod",
                "overrides",
                "start",
                "status",
                "upkeep",
            ],
        ],
    ),
    (
        "runtime",
        &[&["shaping"], &["tick"], &["job"], &["mod", "run"]],
    ),
];

/// The children of `src/<module>/`: its files (but `mod.rs` and `tests.rs`) and folders.
fn children(module: &str) -> BTreeSet<String> {
    std::fs::read_dir(root().join("src").join(module))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter_map(|p| {
            let name = p.file_name()?.to_str()?.to_string();
            if p.is_dir() {
                Some(name)
            } else {
                let stem = name.strip_suffix(".rs")?;
                (stem != "mod" && stem != "tests").then(|| stem.to_string())
            }
        })
        .collect()
}

/// The module path of a file under `src/`: `daemon/http/mod.rs` → `[daemon, http]`.
fn module_path(rel: &str) -> Vec<String> {
    let mut parts: Vec<String> = rel.split('/').map(str::to_string).collect();
    let last = parts.pop().unwrap();
    if last != "mod.rs" && last != "lib.rs" && last != "main.rs" {
        parts.push(last.trim_end_matches(".rs").to_string());
    }
    parts
}

/// Imports between the children of `module` (`mod` for its `mod.rs`): (from, to) → the first
/// place that does it.
fn inner_imports(module: &str) -> BTreeMap<(String, String), String> {
    let kids = children(module);
    let child_of = |path: &[String]| -> Option<String> {
        if path.first().map(String::as_str) != Some(module) {
            return None;
        }
        Some(match path.get(1) {
            Some(name) if kids.contains(name) => name.clone(),
            _ => "mod".to_string(),
        })
    };
    let mut edges = BTreeMap::new();
    for path in rust_files(&root().join("src").join(module)) {
        let rel = rel(&path);
        if rel.ends_with("/tests.rs") {
            continue;
        }
        let here = module_path(&rel);
        let from = child_of(&here).unwrap();
        let code = code_without_tests(&std::fs::read_to_string(&path).unwrap());
        for (target, line) in module_paths(&code, &here) {
            let Some(to) = child_of(&target) else {
                continue;
            };
            if to != from {
                edges
                    .entry((from.clone(), to.clone()))
                    .or_insert_with(|| format!("src/{rel}:{line}: {}", target.join("::")));
            }
        }
    }
    edges
}

#[test]
fn no_child_of_daemon_or_runtime_imports_from_a_floor_above_it() {
    let mut problems = Vec::new();
    for (module, floors) in INNER_FLOORS {
        let floor_of = |child: &str| floors.iter().position(|f| f.contains(&child));
        let mut listed: BTreeSet<String> = children(module);
        listed.insert("mod".to_string());
        let floored: BTreeSet<String> = floors
            .iter()
            .flat_map(|f| f.iter().map(|c| c.to_string()))
            .collect();
        if listed != floored {
            problems.push(format!(
                "src/{module}/: children {listed:?}, floors list {floored:?}"
            ));
            continue;
        }
        for ((from, to), place) in inner_imports(module) {
            let (f, t) = (floor_of(&from).unwrap(), floor_of(&to).unwrap());
            if t > f {
                problems.push(format!(
                    "{place}: `{module}::{from}` (floor {f}) imports `{module}::{to}` (floor {t})"
                ));
            }
        }
    }
    assert!(
        problems.is_empty(),
        "imports that run up a floor inside a module:\n  {}",
        problems.join("\n  ")
    );
}

/// Prints the inner import graphs (`cargo test --test it architecture::print -- --ignored
/// --nocapture`), for laying out INNER_FLOORS.
#[test]
#[ignore]
fn print_inner_imports() {
    for module in ["daemon", "runtime"] {
        for ((from, to), place) in inner_imports(module) {
            println!("{module}: {from} -> {to}   {place}");
        }
    }
    for (name, files) in impl_files() {
        if files.len() > MAX_IMPL_FILES {
            println!("{name}: {}", files.len());
        }
    }
    for ((name, from, to), methods) in method_calls_across_files() {
        let methods: Vec<String> = methods.into_iter().collect();
        println!("{name}: {from} -> {to}   ({})", methods.join(", "));
    }
    for (name, circles) in call_circles() {
        for c in circles {
            println!(
                "{name} circle: {}",
                c.into_iter().collect::<Vec<_>>().join(", ")
            );
        }
    }
}

/// Every type on `WIDE_TYPES` is a debt ARCHITECTURE.md names, with its count.
#[test]
fn architecture_md_names_every_wide_type() {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let debts = text
        .split("\n## Debts")
        .nth(1)
        .expect("ARCHITECTURE.md has a `## Debts` section");
    for (name, n) in WIDE_TYPES {
        let said = format!("`{name}` spans {n} files");
        assert!(debts.contains(&said), "ARCHITECTURE.md, Debts: no {said:?}");
    }
    for (name, n) in CALL_CIRCLES {
        let said = format!("`{name}`'s files call round a circle of {n}");
        assert!(debts.contains(&said), "ARCHITECTURE.md, Debts: no {said:?}");
    }
}
