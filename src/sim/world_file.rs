//! Floor-plan world files: a small line-based text format for simulated
//! worlds, and the built-in worlds under short names.
//!
//! One statement per line; `#` starts a comment (outside a quoted name) and
//! blank lines are ignored. Lengths are in metres, angles in degrees.
//!
//! ```text
//! # comments and blank lines ignored; lengths in metres, angles in degrees
//! name "Zhang & Ghosh lab"
//! start 1.0 1.0 0          # robot start pose x y heading(deg)
//! wall 0 0 10 0            # x1 y1 x2 y2
//! polyline closed 0 0  12 0  12 10  0 10     # or `polyline open ...`
//! box 5 5  0.5 0.3  30      # centre x y, half sizes, angle(deg)
//! ```
//!
//! - `name "…"`: optional, at most once; one double-quoted string in which
//!   `\"`, `\\`, `\n`, `\r` and `\t` are the usual escapes.
//! - `start x y heading`: required, exactly once: a simulation needs to
//!   know where the robot stands, and a guessed default could put it
//!   inside furniture. It must lie within the walls' bounding box.
//! - `wall x1 y1 x2 y2`: one wall.
//! - `polyline open|closed x y x y …`: walls through the points (at least
//!   2; at least 3 when `closed`, which adds the wall back to the first).
//! - `box cx cy hx hy angle`: the four walls of a rectangle with half sizes
//!   `hx`, `hy` > 0, turned by `angle`.
//!
//! Every wall must be at least [`MIN_WALL_LENGTH`] long, every coordinate
//! within [`MAX_COORDINATE`] of the origin, all walls within a
//! [`MAX_EXTENT`] square, and there may be at most [`MAX_WALLS`] walls.
//! Errors name the 1-based line and what is wrong with it. Parsing never
//! panics, whatever the input.

use std::fmt::Write as _;
use std::io::Read as _;
use std::path::{Path, PathBuf};

use thiserror::Error;

use super::world::World;
use crate::geometry::Pose2;

/// Shortest wall accepted (m): shorter ones are typing mistakes (a repeated
/// point) and have no direction a laser could see.
pub const MIN_WALL_LENGTH: f64 = 1e-3;
/// Largest side (m) of the square all walls must fit in: 1 km, far beyond
/// any building the LMS200 (8 m / 80 m range) would map in one run.
pub const MAX_EXTENT: f64 = 1000.0;
/// Largest distance (m) of any coordinate from the origin, so coordinates
/// keep sub-micrometre resolution in `f64`.
pub const MAX_COORDINATE: f64 = 1e5;
/// Most walls in one world: ray casting and the exploration tests stay
/// fast, and a runaway generator is caught early.
pub const MAX_WALLS: usize = 100_000;
/// Largest world file read (bytes): 64 MiB, far above `MAX_WALLS` lines.
pub const MAX_FILE_BYTES: u64 = 64 << 20;

/// Longest piece of offending text quoted in an error message (chars).
const QUOTE_CHARS: usize = 40;

/// What is wrong with one line of a world file.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LineProblem {
    #[error("unknown keyword `{0}` (expected name, start, wall, polyline or box)")]
    UnknownKeyword(String),
    #[error("`{keyword}` takes {expected}, found {found} value(s)")]
    ValueCount {
        keyword: &'static str,
        expected: &'static str,
        found: usize,
    },
    #[error("`{0}` is not a number")]
    BadNumber(String),
    #[error("`{0}` is not a finite number")]
    NonFinite(String),
    #[error("coordinate {0} m is more than {MAX_COORDINATE} m from the origin")]
    TooFar(f64),
    #[error("wall from ({}, {}) to ({}, {}) is shorter than {MIN_WALL_LENGTH} m", .a[0], .a[1], .b[0], .b[1])]
    ShortWall { a: [f64; 2], b: [f64; 2] },
    #[error("a {kind} polyline needs at least {min} points, found {found}")]
    TooFewPoints {
        kind: &'static str,
        min: usize,
        found: usize,
    },
    #[error("polyline coordinates come in x y pairs, found {0} value(s)")]
    OddCoordinates(usize),
    #[error("polyline kind `{0}` is neither `open` nor `closed`")]
    PolylineKind(String),
    #[error("box half sizes {0} m and {1} m must both be positive")]
    BoxHalfSize(f64, f64),
    #[error("`name` takes one double-quoted string")]
    Name,
    #[error("unterminated quoted string")]
    UnterminatedQuote,
    #[error("unknown escape `\\{0}` in a quoted string")]
    BadEscape(char),
    #[error("a quoted string is only allowed after `name`")]
    UnexpectedString,
    #[error("`{keyword}` already given on line {first}")]
    Duplicate { keyword: &'static str, first: usize },
    #[error("the walls span {0:.1} m, more than the {MAX_EXTENT} m limit")]
    TooLarge(f64),
    #[error("more than {MAX_WALLS} walls")]
    TooManyWalls,
    #[error("start ({0}, {1}) lies outside the walls' bounding box")]
    StartOutside(f64, f64),
}

/// Why a world file could not be read.
#[derive(Debug, Error)]
pub enum WorldFileError {
    #[error("cannot read world file {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("world file {path} is larger than {MAX_FILE_BYTES} bytes")]
    FileTooLarge { path: PathBuf },
    #[error("line {line}: {problem}")]
    Line { line: usize, problem: LineProblem },
    #[error("no `start x y heading` line: the robot's start pose is required")]
    MissingStart,
    #[error("no walls: a world needs at least one `wall`, `polyline` or `box` line")]
    EmptyWorld,
}

/// A world with its name and the robot's start pose.
#[derive(Debug, Clone)]
pub struct WorldFile {
    /// Free-form name (empty when the file gives none).
    pub name: String,
    /// The walls.
    pub world: World,
    /// Where the robot starts (m, rad; map frame).
    pub start: Pose2,
}

/// One token of a line: a bare word or a quoted string (unescaped).
#[derive(Debug, PartialEq)]
enum Token<'a> {
    Bare(&'a str),
    Quoted(String),
}

/// The first `QUOTE_CHARS` characters of `s`, for error messages.
fn quote(s: &str) -> String {
    let mut q: String = s.chars().take(QUOTE_CHARS).collect();
    if s.chars().nth(QUOTE_CHARS).is_some() {
        q.push('…');
    }
    q
}

/// Splits `line` into tokens, dropping a trailing comment.
fn tokenize(line: &str) -> Result<Vec<Token<'_>>, LineProblem> {
    let mut tokens = Vec::new();
    let mut rest = line;
    loop {
        rest = rest.trim_start();
        let Some(c) = rest.chars().next() else {
            return Ok(tokens);
        };
        match c {
            '#' => return Ok(tokens),
            '"' => {
                let mut text = String::new();
                let mut chars = rest.char_indices().skip(1);
                let mut end = None;
                while let Some((i, c)) = chars.next() {
                    match c {
                        '"' => {
                            end = Some(i + 1);
                            break;
                        }
                        '\\' => match chars.next().map(|(_, e)| e) {
                            Some('"') => text.push('"'),
                            Some('\\') => text.push('\\'),
                            Some('n') => text.push('\n'),
                            Some('r') => text.push('\r'),
                            Some('t') => text.push('\t'),
                            Some(e) => return Err(LineProblem::BadEscape(e)),
                            None => return Err(LineProblem::UnterminatedQuote),
                        },
                        c => text.push(c),
                    }
                }
                let end = end.ok_or(LineProblem::UnterminatedQuote)?;
                tokens.push(Token::Quoted(text));
                rest = rest.get(end..).unwrap_or("");
            }
            _ => {
                let end = rest
                    .find(|c: char| c.is_whitespace() || c == '#' || c == '"')
                    .unwrap_or(rest.len());
                let (word, tail) = rest.split_at(end);
                tokens.push(Token::Bare(word));
                rest = tail;
            }
        }
    }
}

/// The numbers of `tokens`, each finite and within `MAX_COORDINATE`.
fn numbers(tokens: &[Token<'_>]) -> Result<Vec<f64>, LineProblem> {
    tokens
        .iter()
        .map(|t| match t {
            Token::Quoted(_) => Err(LineProblem::UnexpectedString),
            Token::Bare(word) => {
                let v: f64 = word
                    .parse()
                    .map_err(|_| LineProblem::BadNumber(quote(word)))?;
                if !v.is_finite() {
                    return Err(LineProblem::NonFinite(quote(word)));
                }
                if v.abs() > MAX_COORDINATE {
                    return Err(LineProblem::TooFar(v));
                }
                Ok(v)
            }
        })
        .collect()
}

/// `values` if there are exactly `n` of them.
fn exactly<const N: usize>(
    keyword: &'static str,
    expected: &'static str,
    values: &[f64],
) -> Result<[f64; N], LineProblem> {
    values.try_into().map_err(|_| LineProblem::ValueCount {
        keyword,
        expected,
        found: values.len(),
    })
}

/// The walls' bounding box, grown one line at a time.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Bounds {
    const EMPTY: Bounds = Bounds {
        lo: [f64::INFINITY; 2],
        hi: [f64::NEG_INFINITY; 2],
    };

    fn grow(&mut self, p: [f64; 2]) {
        self.lo = [self.lo[0].min(p[0]), self.lo[1].min(p[1])];
        self.hi = [self.hi[0].max(p[0]), self.hi[1].max(p[1])];
    }

    /// The larger side (m); 0 when empty.
    fn span(&self) -> f64 {
        (self.hi[0] - self.lo[0])
            .max(self.hi[1] - self.lo[1])
            .max(0.0)
    }

    fn contains(&self, p: [f64; 2]) -> bool {
        self.lo[0] <= p[0] && p[0] <= self.hi[0] && self.lo[1] <= p[1] && p[1] <= self.hi[1]
    }
}

/// Checks `walls` (the walls of one line) and appends them to `all`.
fn push_walls(
    all: &mut Vec<[[f64; 2]; 2]>,
    bounds: &mut Bounds,
    walls: &[[[f64; 2]; 2]],
) -> Result<(), LineProblem> {
    if walls.len() > MAX_WALLS.saturating_sub(all.len()) {
        return Err(LineProblem::TooManyWalls);
    }
    for &[a, b] in walls {
        // Coordinates are finite and within `MAX_COORDINATE`: no NaN here.
        if (b[0] - a[0]).hypot(b[1] - a[1]) < MIN_WALL_LENGTH {
            return Err(LineProblem::ShortWall { a, b });
        }
        bounds.grow(a);
        bounds.grow(b);
    }
    let span = bounds.span();
    if span > MAX_EXTENT {
        return Err(LineProblem::TooLarge(span));
    }
    all.extend_from_slice(walls);
    Ok(())
}

/// Writes `s` as a double-quoted string with the escapes the parser reads.
fn write_quoted(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c => out.push(c),
        }
    }
    out.push('"');
}

impl WorldFile {
    /// Names accepted by [`WorldFile::builtin`].
    pub const BUILTIN_NAMES: &'static [&'static str] =
        &["loop", "room", "corridor", "lab", "office"];

    /// Parses a world file's text (see the module documentation).
    pub fn parse(text: &str) -> Result<WorldFile, WorldFileError> {
        let mut walls: Vec<[[f64; 2]; 2]> = Vec::new();
        let mut bounds = Bounds::EMPTY;
        let mut name: Option<(String, usize)> = None;
        let mut start: Option<(Pose2, usize)> = None;
        for (index, line) in text.lines().enumerate() {
            let line_no = index + 1;
            let at = |problem| WorldFileError::Line {
                line: line_no,
                problem,
            };
            let tokens = tokenize(line).map_err(at)?;
            let Some((keyword, args)) = tokens.split_first() else {
                continue;
            };
            let keyword = match keyword {
                Token::Bare(k) => *k,
                Token::Quoted(_) => return Err(at(LineProblem::UnexpectedString)),
            };
            match keyword {
                "name" => {
                    if let Some((_, first)) = name {
                        return Err(at(LineProblem::Duplicate {
                            keyword: "name",
                            first,
                        }));
                    }
                    match args {
                        [Token::Quoted(s)] => name = Some((s.clone(), line_no)),
                        _ => return Err(at(LineProblem::Name)),
                    }
                }
                "start" => {
                    if let Some((_, first)) = start {
                        return Err(at(LineProblem::Duplicate {
                            keyword: "start",
                            first,
                        }));
                    }
                    let v = numbers(args).map_err(at)?;
                    let [x, y, heading] =
                        exactly("start", "3 values (x y heading)", &v).map_err(at)?;
                    start = Some((Pose2::new(x, y, heading.to_radians()), line_no));
                }
                "wall" => {
                    let v = numbers(args).map_err(at)?;
                    let [x1, y1, x2, y2] =
                        exactly("wall", "4 values (x1 y1 x2 y2)", &v).map_err(at)?;
                    push_walls(&mut walls, &mut bounds, &[[[x1, y1], [x2, y2]]]).map_err(at)?;
                }
                "polyline" => {
                    let (kind, coords) = match args.split_first() {
                        Some((Token::Bare(kind), coords)) => (*kind, coords),
                        Some((Token::Quoted(_), _)) => {
                            return Err(at(LineProblem::UnexpectedString));
                        }
                        None => {
                            return Err(at(LineProblem::ValueCount {
                                keyword: "polyline",
                                expected: "`open` or `closed` and at least 2 points",
                                found: 0,
                            }));
                        }
                    };
                    let (kind, closed, min) = match kind {
                        "open" => ("open", false, 2),
                        "closed" => ("closed", true, 3),
                        other => return Err(at(LineProblem::PolylineKind(quote(other)))),
                    };
                    if coords.len() % 2 != 0 {
                        return Err(at(LineProblem::OddCoordinates(coords.len())));
                    }
                    if coords.len() / 2 < min {
                        return Err(at(LineProblem::TooFewPoints {
                            kind,
                            min,
                            found: coords.len() / 2,
                        }));
                    }
                    if coords.len() / 2 > MAX_WALLS + 1 {
                        return Err(at(LineProblem::TooManyWalls));
                    }
                    let v = numbers(coords).map_err(at)?;
                    let points: Vec<[f64; 2]> = v.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
                    let mut edges: Vec<[[f64; 2]; 2]> =
                        points.windows(2).map(|w| [w[0], w[1]]).collect();
                    if closed && let (Some(&first), Some(&last)) = (points.first(), points.last()) {
                        edges.push([last, first]);
                    }
                    push_walls(&mut walls, &mut bounds, &edges).map_err(at)?;
                }
                "box" => {
                    let v = numbers(args).map_err(at)?;
                    let [cx, cy, hx, hy, angle] =
                        exactly("box", "5 values (cx cy hx hy angle)", &v).map_err(at)?;
                    if hx <= 0.0 || hy <= 0.0 {
                        return Err(at(LineProblem::BoxHalfSize(hx, hy)));
                    }
                    // The same corners as `World::add_box`, so a box in a
                    // file gives exactly the walls of the same box in code.
                    let mut shape = World::new();
                    shape.add_box([cx, cy], [hx, hy], angle.to_radians());
                    push_walls(&mut walls, &mut bounds, shape.walls()).map_err(at)?;
                }
                other => return Err(at(LineProblem::UnknownKeyword(quote(other)))),
            }
        }
        let (start, start_line) = start.ok_or(WorldFileError::MissingStart)?;
        if walls.is_empty() {
            return Err(WorldFileError::EmptyWorld);
        }
        if !bounds.contains([start.x, start.y]) {
            return Err(WorldFileError::Line {
                line: start_line,
                problem: LineProblem::StartOutside(start.x, start.y),
            });
        }
        Ok(WorldFile {
            name: name.map(|(n, _)| n).unwrap_or_default(),
            world: World::from_segments(walls),
            start,
        })
    }

    /// Reads and parses the world file at `path`.
    pub fn load(path: &Path) -> Result<WorldFile, WorldFileError> {
        let io = |source| WorldFileError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let mut text = String::new();
        file.take(MAX_FILE_BYTES + 1)
            .read_to_string(&mut text)
            .map_err(io)?;
        if text.len() as u64 > MAX_FILE_BYTES {
            return Err(WorldFileError::FileTooLarge {
                path: path.to_path_buf(),
            });
        }
        WorldFile::parse(&text)
    }

    /// The world as text: the name, the start pose and every wall as a
    /// `wall` line. Numbers are written in Rust's shortest round-trip form,
    /// so parsing the text gives the same walls bit for bit (the heading
    /// goes through degrees and may move by an ulp).
    pub fn to_text(&self) -> String {
        let mut out = String::from("name ");
        write_quoted(&mut out, &self.name);
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "\nstart {} {} {}",
            self.start.x,
            self.start.y,
            self.start.theta.to_degrees()
        );
        for [a, b] in self.world.walls() {
            let _ = writeln!(out, "wall {} {} {} {}", a[0], a[1], b[0], b[1]);
        }
        out
    }

    /// A built-in world by name (see [`WorldFile::BUILTIN_NAMES`]):
    /// - `loop`: [`World::loop_around_block`], start (1, 1, 0);
    /// - `room`: [`World::room_with_boxes`], start (4.5, 3, 0);
    /// - `corridor`: [`World::corridor_with_doors`], start (1, 0, 0);
    /// - `lab`: [`World::paper_lab`], start (2, 2, 0);
    /// - `office`: [`World::corridor_with_rooms`], start (1, 0, 0).
    pub fn builtin(name: &str) -> Option<WorldFile> {
        let (title, world, start) = match name {
            "loop" => (
                "loop around a block",
                World::loop_around_block(),
                Pose2::new(1.0, 1.0, 0.0),
            ),
            "room" => (
                "room with boxes",
                World::room_with_boxes(),
                Pose2::new(4.5, 3.0, 0.0),
            ),
            "corridor" => (
                "corridor with doors",
                World::corridor_with_doors(),
                Pose2::new(1.0, 0.0, 0.0),
            ),
            "lab" => (
                "Zhang & Ghosh lab",
                World::paper_lab(),
                Pose2::new(2.0, 2.0, 0.0),
            ),
            "office" => (
                "corridor with rooms",
                World::corridor_with_rooms(),
                Pose2::new(1.0, 0.0, 0.0),
            ),
            _ => return None,
        };
        Some(WorldFile {
            name: title.to_string(),
            world,
            start,
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests;
