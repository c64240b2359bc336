//! Reading Rust source as text: code without comments and literals, without inline test
//! modules, the `crate::`/`super::` paths it names, and the types its `impl` blocks extend.

/// The source with comments, string literals and char literals blanked out (newlines kept,
/// so line numbers still count), so that paths are only found in code.
pub fn code_only(text: &str) -> String {
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
pub fn crate_paths(code: &str) -> Vec<(String, usize)> {
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

/// The line ranges (0-based, end exclusive) of the inline test modules in `code` (as
/// `code_only` gives it): a `#[cfg(test)]` line, then `mod NAME {` up to its closing brace.
pub fn inline_test_modules(code: &str) -> Vec<std::ops::Range<usize>> {
    let lines: Vec<&str> = code.lines().collect();
    let mut found = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let opens_test_module = lines[i].trim() == "#[cfg(test)]"
            && lines.get(i + 1).is_some_and(|next| {
                let next = next.trim_start();
                (next.starts_with("mod ") || next.starts_with("pub mod ")) && next.contains('{')
            });
        if !opens_test_module {
            i += 1;
            continue;
        }
        let mut depth = 0i64;
        let mut end = lines.len();
        'scan: for (j, line) in lines.iter().enumerate().skip(i + 1) {
            for c in line.chars() {
                match c {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            end = j + 1;
                            break 'scan;
                        }
                    }
                    _ => {}
                }
            }
        }
        found.push(i..end);
        i = end;
    }
    found
}

/// `code_only(text)` with the inline test modules blanked (lines kept, so numbers count).
pub fn code_without_tests(text: &str) -> String {
    let code = code_only(text);
    let tests = inline_test_modules(&code);
    code.lines()
        .enumerate()
        .map(|(i, line)| {
            if tests.iter().any(|r| r.contains(&i)) {
                ""
            } else {
                line
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The types extended by the inherent `impl` blocks of `code` (`impl<T> Name<T> {`, not
/// `impl Trait for Name`), with the line of each.
pub fn inherent_impls(code: &str) -> Vec<(String, usize)> {
    let mut found = Vec::new();
    for (i, line) in code.lines().enumerate() {
        let Some(mut rest) = line.trim_start().strip_prefix("impl") else {
            continue;
        };
        if rest.starts_with('<') {
            let mut depth = 0;
            let mut cut = rest.len();
            for (k, c) in rest.char_indices() {
                match c {
                    '<' => depth += 1,
                    '>' => {
                        depth -= 1;
                        if depth == 0 {
                            cut = k + 1;
                            break;
                        }
                    }
                    _ => {}
                }
            }
            rest = &rest[cut..];
        } else if !rest.starts_with(' ') {
            continue; // `impl_something`
        }
        let head = rest.split(['{']).next().unwrap_or("");
        let head = head.split(" where").next().unwrap_or("").trim();
        if head.is_empty() || head.contains(" for ") {
            continue;
        }
        let path = head.split('<').next().unwrap_or("");
        let name = path.rsplit("::").next().unwrap_or("").trim();
        if name.chars().next().is_some_and(char::is_uppercase) {
            found.push((name.to_string(), i + 1));
        }
    }
    found
}

/// Every module path named by a `crate::`, `super::` or `self::` path in `code`, resolved
/// against `here` (the module path of the file: `["daemon", "http"]` for
/// `src/daemon/http/mod.rs`), as the absolute path's first names, with the line.
pub fn module_paths(code: &str, here: &[String]) -> Vec<(Vec<String>, usize)> {
    let mut found = Vec::new();
    let bytes = code.as_bytes();
    let mut i = 0;
    while i < code.len() {
        let rest = &code[i..];
        let starts = ["crate::", "super::", "self::"]
            .iter()
            .find(|p| rest.starts_with(*p))
            .copied();
        // `pub(in crate::x)` names a visibility, not an import.
        let preceded = i > 0
            && (bytes[i - 1].is_ascii_alphanumeric()
                || bytes[i - 1] == b'_'
                || bytes[i - 1] == b':'
                || code[..i].ends_with("(in "));
        let Some(start) = starts.filter(|_| !preceded) else {
            i += rest.chars().next().map_or(1, char::len_utf8);
            continue;
        };
        let line = code[..i].matches('\n').count() + 1;
        let mut base: Vec<String> = match start {
            "crate::" => Vec::new(),
            "self::" => here.to_vec(),
            _ => here[..here.len().saturating_sub(1)].to_vec(),
        };
        let mut j = i + start.len();
        while code[j..].starts_with("super::") {
            base.pop();
            j += "super::".len();
        }
        let tail = &code[j..];
        if let Some(group) = tail.strip_prefix('{') {
            // The group's first names at depth 0: `super::{a::X, b}` names a and b.
            let mut depth = 0;
            let mut name = String::new();
            let mut expect = true;
            for c in group.chars() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => expect = true,
                    c if depth == 0 && expect && (c.is_alphanumeric() || c == '_') => name.push(c),
                    _ => {
                        if !name.is_empty() {
                            let mut path = base.clone();
                            path.push(std::mem::take(&mut name));
                            found.push((path, line));
                        }
                        if depth == 0 && !c.is_whitespace() {
                            expect = false;
                        }
                    }
                }
            }
            if !name.is_empty() {
                let mut path = base.clone();
                path.push(name);
                found.push((path, line));
            }
        } else {
            let mut path = base;
            let names = tail
                .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                .next()
                .unwrap_or("");
            for name in names.split("::").filter(|n| !n.is_empty()).take(2) {
                path.push(name.to_string());
            }
            found.push((path, line));
        }
        i = j;
    }
    found
}

/// An inherent `impl` block: its type, the methods it defines and the methods it calls on
/// `self` (`self.name(…)`, `Self::name(…)`), by name.
pub struct ImplBlock {
    pub name: String,
    pub defines: Vec<String>,
    pub calls: std::collections::BTreeSet<String>,
}

/// The inherent `impl` blocks of `code` (as [`code_only`] leaves it: its braces balance).
pub fn impl_blocks(code: &str) -> Vec<ImplBlock> {
    let line_starts: Vec<usize> = std::iter::once(0)
        .chain(code.match_indices('\n').map(|(i, _)| i + 1))
        .collect();
    let bytes = code.as_bytes();
    let mut blocks = Vec::new();
    for (name, line) in inherent_impls(code) {
        let Some(open) = code[line_starts[line - 1]..]
            .find('{')
            .map(|k| k + line_starts[line - 1])
        else {
            continue;
        };
        let mut depth = 0usize;
        let mut close = code.len();
        for (k, &b) in bytes.iter().enumerate().skip(open) {
            match b {
                b'{' => depth += 1,
                b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        close = k;
                        break;
                    }
                }
                _ => {}
            }
        }
        let body = &code[open + 1..close];
        blocks.push(ImplBlock {
            name,
            defines: words_after(body, "fn").map(|(w, _)| w).collect(),
            calls: self_calls(body),
        });
    }
    blocks
}

/// The identifiers that follow the word `keyword` in `code`, with what follows them.
fn words_after<'a>(code: &'a str, keyword: &'a str) -> impl Iterator<Item = (String, &'a str)> {
    code.match_indices(keyword).filter_map(move |(at, _)| {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            return None;
        }
        let rest = &code[at + keyword.len()..];
        if !rest.starts_with(char::is_whitespace) {
            return None;
        }
        let rest = rest.trim_start();
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        (end > 0).then(|| (rest[..end].to_string(), &rest[end..]))
    })
}

/// The methods `code` calls on `self` or `Self`, whitespace and line breaks allowed around
/// the `.` and before the parenthesis (as rustfmt breaks a long call).
fn self_calls(code: &str) -> std::collections::BTreeSet<String> {
    let mut calls = std::collections::BTreeSet::new();
    for (at, _) in code.match_indices("self") {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue;
        }
        let rest = code[at + 4..].trim_start();
        let Some(rest) = rest.strip_prefix('.') else {
            continue;
        };
        let rest = rest.trim_start();
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        if end > 0 && rest[end..].trim_start().starts_with(['(', ':']) {
            calls.insert(rest[..end].to_string());
        }
    }
    for (at, _) in code.match_indices("Self::") {
        let rest = &code[at + 6..];
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        if end > 0 && rest[end..].trim_start().starts_with('(') {
            calls.insert(rest[..end].to_string());
        }
    }
    calls
}
