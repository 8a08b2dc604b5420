//! clsmap: a SICK LMS200 driver and Closed Line Segment mapper
//! (after Zhang & Ghosh, ICRA 2000) for holonomic robots.

pub mod daemon;
#[cfg(feature = "sim")]
pub mod demo;
pub mod eval;
pub mod explore;
pub mod files;
pub mod geometry;
pub mod graph;
pub mod input;
pub mod localize;
pub mod map;
pub mod pipeline;
pub mod render;
pub mod ros2;
#[cfg(feature = "sim")]
pub mod sim;

/// An error and its causes on one line, outermost first: what failed and
/// why, for a log line or a status report.
pub fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}

#[cfg(test)]
mod layers {
    use std::path::{Path, PathBuf};

    /// The layers of the crate, lowest first, and what each module may use
    /// besides the crate root's helpers: a module imports only from layers
    /// below its own (its tests may use the simulator and test helpers).
    const LAYERS: &[(&str, &[&str])] = &[
        ("geometry", &[]),
        ("files", &["geometry"]),
        ("ros2", &[]),
        ("input", &["geometry", "files", "ros2"]),
        ("sim", &["geometry"]),
        ("eval", &["geometry", "files"]),
        ("map", &["geometry", "files"]),
        ("localize", &["geometry", "map"]),
        ("render", &["geometry", "map"]),
        ("explore", &["geometry", "map"]),
        ("graph", &["geometry", "map", "localize"]),
        (
            "pipeline",
            &[
                "geometry", "files", "input", "eval", "map", "localize", "render", "graph", "ros2",
            ],
        ),
        (
            "daemon",
            &[
                "geometry", "files", "input", "eval", "map", "localize", "render", "graph", "ros2",
                "pipeline", "explore", "sim",
            ],
        ),
        (
            "demo",
            &[
                "geometry", "files", "input", "eval", "map", "localize", "render", "graph", "ros2",
                "pipeline", "explore", "sim", "daemon",
            ],
        ),
    ];

    /// The `.rs` files of module `name` (a directory or one file), tests
    /// files left out.
    fn sources(src: &Path, name: &str) -> Vec<PathBuf> {
        let file = src.join(format!("{name}.rs"));
        let mut out = Vec::new();
        let mut dirs = vec![src.join(name)];
        if file.is_file() {
            out.push(file);
        }
        while let Some(dir) = dirs.pop() {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            for entry in entries.flatten() {
                let path = entry.path();
                if path.is_dir() {
                    dirs.push(path);
                } else if path.extension().is_some_and(|e| e == "rs")
                    && path.file_name().is_some_and(|n| n != "tests.rs")
                {
                    out.push(path);
                }
            }
        }
        out
    }

    /// `text` without its comment lines and without the items marked
    /// `#[cfg(test)]` (a `mod … { … }` block, found by its braces, or a
    /// one-line `use`/`mod`), wherever they stand in the file.
    fn code_without_tests(text: &str) -> String {
        let lines: Vec<&str> = text
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect();
        let mut out = String::new();
        let mut k = 0;
        while k < lines.len() {
            if lines[k].trim() != "#[cfg(test)]" {
                out.push_str(lines[k]);
                out.push('\n');
                k += 1;
                continue;
            }
            // Skip the marked item: attributes, then its lines up to the
            // `;` of a one-liner or the brace closing its block.
            k += 1;
            while k < lines.len() && lines[k].trim_start().starts_with("#[") {
                k += 1;
            }
            let (mut depth, mut opened) = (0i64, false);
            while k < lines.len() {
                let line = lines[k];
                k += 1;
                opened |= line.contains('{');
                depth += line.matches('{').count() as i64 - line.matches('}').count() as i64;
                if (!opened && line.trim_end().ends_with(';')) || (opened && depth <= 0) {
                    break;
                }
            }
        }
        out
    }

    /// The top-level modules `crate::…` names in the code (not comments,
    /// not `#[cfg(test)]` items) of `text`, grouped imports included.
    fn used_modules(text: &str) -> Vec<String> {
        let code = code_without_tests(text);
        let name_at = |s: &str| -> String {
            s.trim_start()
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect()
        };
        let mut used = Vec::new();
        for (i, _) in code.match_indices("crate::") {
            let rest = &code[i + "crate::".len()..];
            if let Some(group) = rest.strip_prefix('{') {
                // `crate::{a, b::c, d::{e, f}}`: the first segment of each
                // top-level item.
                let mut depth = 0;
                let mut item_start = true;
                for (k, c) in group.char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => break,
                        '}' => depth -= 1,
                        ',' if depth == 0 => item_start = true,
                        _ if item_start && !c.is_whitespace() => {
                            item_start = false;
                            let name = name_at(&group[k..]);
                            if !name.is_empty() {
                                used.push(name);
                            }
                        }
                        _ => {}
                    }
                }
            } else {
                let name = name_at(rest);
                if !name.is_empty() {
                    used.push(name);
                }
            }
        }
        used
    }

    #[test]
    fn no_module_imports_from_a_layer_above_its_own() {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        let layered: Vec<&str> = LAYERS.iter().map(|(m, _)| *m).collect();
        let mut wrong = Vec::new();
        for (module, allowed) in LAYERS {
            let files = sources(&src, module);
            assert!(!files.is_empty(), "no sources for module {module}");
            for file in files {
                let text = std::fs::read_to_string(&file).expect("readable source");
                for used in used_modules(&text) {
                    let is_module = layered.contains(&used.as_str());
                    if is_module && used != *module && !allowed.contains(&used.as_str()) {
                        wrong.push(format!("{} uses crate::{used}", file.display()));
                    }
                }
            }
        }
        wrong.sort();
        wrong.dedup();
        assert!(
            wrong.is_empty(),
            "imports against the layering:\n{}",
            wrong.join("\n")
        );
    }

    #[test]
    fn every_module_of_the_crate_has_a_layer() {
        let lib = include_str!("lib.rs");
        for line in lib.lines() {
            if let Some(name) = line.strip_prefix("pub mod ") {
                let name = name.trim_end_matches(';');
                assert!(
                    LAYERS.iter().any(|(m, _)| *m == name),
                    "module {name} has no layer in LAYERS"
                );
            }
        }
    }

    #[test]
    fn the_check_sees_an_import_in_code_and_not_in_comments_or_tests() {
        let text = "use crate::daemon::Core;\n// crate::sim in a comment\nfn f() {}\n#[cfg(test)]\nmod tests { use crate::sim::Rng; }\n";
        assert_eq!(used_modules(text), vec!["daemon".to_string()]);
        // Test items anywhere in the file, and code after them.
        let text = "#[cfg(test)]\nuse crate::sim::Rng;\n#[cfg(test)]\n#[allow(dead_code)]\nmod checks {\n    fn g() { crate::sim::x(); }\n}\nfn h() { crate::graph::y(); }\n";
        assert_eq!(used_modules(text), vec!["graph".to_string()]);
        // Grouped imports.
        let text = "use crate::{\n    geometry::Pose2,\n    map::{Edge, cls::ClsMap},\n    pipeline,\n};\n";
        assert_eq!(used_modules(text), vec!["geometry", "map", "pipeline"]);
    }
}
