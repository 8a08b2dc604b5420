use super::*;
use proptest::prelude::*;

const EXAMPLE: &str = r#"
# comments and blank lines ignored; lengths in metres, angles in degrees
name "Zhang & Ghosh lab"
start 1.0 1.0 0          # robot start pose x y heading(deg)
wall 0 0 10 0            # x1 y1 x2 y2
polyline closed 0 0  12 0  12 10  0 10     # or `polyline open ...`
box 5 5  0.5 0.3  30      # centre x y, half sizes, angle(deg)
"#;

/// The line and problem of a parse error, or a panic for other errors.
fn line_error(text: &str) -> (usize, LineProblem) {
    match WorldFile::parse(text) {
        Err(WorldFileError::Line { line, problem }) => (line, problem),
        other => panic!("expected a line error for {text:?}, got {other:?}"),
    }
}

#[test]
fn parses_the_documented_example() {
    let f = WorldFile::parse(EXAMPLE).unwrap();
    assert_eq!(f.name, "Zhang & Ghosh lab");
    assert_eq!(f.start, Pose2::new(1.0, 1.0, 0.0));
    let walls = f.world.walls();
    assert_eq!(walls.len(), 1 + 4 + 4);
    assert_eq!(walls[0], [[0.0, 0.0], [10.0, 0.0]]);
    assert_eq!(
        walls[4],
        [[0.0, 10.0], [0.0, 0.0]],
        "closed back to the start"
    );
    let mut turned = World::new();
    turned.add_box([5.0, 5.0], [0.5, 0.3], 30f64.to_radians());
    assert_eq!(&walls[5..], turned.walls());
    // The box is turned by 30°: its first side runs at 30°.
    let [a, b] = walls[5];
    let dir = (b[1] - a[1]).atan2(b[0] - a[0]);
    assert!((dir - 30f64.to_radians()).abs() < 1e-12);
}

#[test]
fn comments_blank_lines_and_crlf_are_ignored() {
    let text = "# only a comment\r\n\r\n   \t\r\nstart 0.5 0.5 90\r\nwall 0 0 1 0#no space\r\nwall 0 0 0 1 # x\r\n";
    let f = WorldFile::parse(text).unwrap();
    assert_eq!(f.name, "");
    assert_eq!(f.world.walls().len(), 2);
    assert!((f.start.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
}

#[test]
fn errors_name_the_line_and_the_problem() {
    let start = "start 0.5 0.5 0\n";
    let cases: Vec<(String, usize, LineProblem)> = vec![
        (
            format!("{start}door 0 0 1 0"),
            2,
            LineProblem::UnknownKeyword("door".into()),
        ),
        (
            format!("{start}wall 0 0 1"),
            2,
            LineProblem::ValueCount {
                keyword: "wall",
                expected: "4 values (x1 y1 x2 y2)",
                found: 3,
            },
        ),
        (
            "start 1 2\nwall 0 0 1 0".into(),
            1,
            LineProblem::ValueCount {
                keyword: "start",
                expected: "3 values (x y heading)",
                found: 2,
            },
        ),
        (
            format!("{start}box 1 1 0.5 0.5"),
            2,
            LineProblem::ValueCount {
                keyword: "box",
                expected: "5 values (cx cy hx hy angle)",
                found: 4,
            },
        ),
        (
            format!("{start}wall 0 0 1,5 0"),
            2,
            LineProblem::BadNumber("1,5".into()),
        ),
        (
            format!("{start}wall 0 0 NaN 0"),
            2,
            LineProblem::NonFinite("NaN".into()),
        ),
        (
            format!("{start}wall 0 0 1 -inf"),
            2,
            LineProblem::NonFinite("-inf".into()),
        ),
        (
            format!("{start}wall 0 0 2e5 0"),
            2,
            LineProblem::TooFar(2e5),
        ),
        (
            format!("{start}\n\nwall 1 1 1 1.0005"),
            4,
            LineProblem::ShortWall {
                a: [1.0, 1.0],
                b: [1.0, 1.0005],
            },
        ),
        (
            format!("{start}polyline open 0 0"),
            2,
            LineProblem::TooFewPoints {
                kind: "open",
                min: 2,
                found: 1,
            },
        ),
        (
            format!("{start}polyline closed 0 0 1 1"),
            2,
            LineProblem::TooFewPoints {
                kind: "closed",
                min: 3,
                found: 2,
            },
        ),
        (
            format!("{start}polyline open 0 0 1"),
            2,
            LineProblem::OddCoordinates(3),
        ),
        (
            format!("{start}polyline shut 0 0 1 0"),
            2,
            LineProblem::PolylineKind("shut".into()),
        ),
        (
            format!("{start}polyline open 0 0 1 0 1 0"),
            2,
            LineProblem::ShortWall {
                a: [1.0, 0.0],
                b: [1.0, 0.0],
            },
        ),
        (
            format!("{start}box 1 1 0 0.5 0"),
            2,
            LineProblem::BoxHalfSize(0.0, 0.5),
        ),
        (format!("{start}name lab"), 2, LineProblem::Name),
        (
            format!("{start}name \"lab"),
            2,
            LineProblem::UnterminatedQuote,
        ),
        (
            format!("{start}name \"a\\qb\""),
            2,
            LineProblem::BadEscape('q'),
        ),
        (
            format!("{start}wall 0 0 \"1\" 0"),
            2,
            LineProblem::UnexpectedString,
        ),
        (
            format!("{start}wall 0 0 1 0\nstart 0 0 0"),
            3,
            LineProblem::Duplicate {
                keyword: "start",
                first: 1,
            },
        ),
        (
            format!("name \"a\"\n{start}name \"b\""),
            3,
            LineProblem::Duplicate {
                keyword: "name",
                first: 1,
            },
        ),
        (
            format!("{start}wall 0 0 1 0\nwall 0 0 0 1000.5"),
            3,
            LineProblem::TooLarge(1000.5),
        ),
        (
            "wall 0 0 1 0\nstart 2 0.5 0\nwall 0 0 0 1".into(),
            2,
            LineProblem::StartOutside(2.0, 0.5),
        ),
    ];
    for (text, line, problem) in cases {
        let got = line_error(&text);
        assert_eq!(got, (line, problem.clone()), "{text:?}");
        let message = WorldFileError::Line { line, problem }.to_string();
        assert!(message.starts_with(&format!("line {line}: ")), "{message}");
    }
}

#[test]
fn start_and_at_least_one_wall_are_required() {
    assert!(matches!(
        WorldFile::parse("wall 0 0 1 0"),
        Err(WorldFileError::MissingStart)
    ));
    assert!(matches!(
        WorldFile::parse("# nothing\nstart 0 0 0\n"),
        Err(WorldFileError::EmptyWorld)
    ));
    assert!(matches!(
        WorldFile::parse(""),
        Err(WorldFileError::MissingStart)
    ));
}

#[test]
fn more_than_the_wall_limit_is_refused() {
    let mut text = String::from("start 0.5 0.5 0\n");
    for _ in 0..MAX_WALLS {
        text.push_str("wall 0 0 1 1\n");
    }
    assert_eq!(
        WorldFile::parse(&text).unwrap().world.walls().len(),
        MAX_WALLS
    );
    text.push_str("wall 0 0 1 0\n");
    assert_eq!(
        line_error(&text),
        (MAX_WALLS + 2, LineProblem::TooManyWalls)
    );
    // One polyline with too many points is refused before its numbers
    // are read.
    let mut line = String::from("start 0 0 0\npolyline open");
    for _ in 0..MAX_WALLS + 2 {
        line.push_str(" 0 0");
    }
    assert_eq!(line_error(&line), (2, LineProblem::TooManyWalls));
}

#[test]
fn long_offending_text_is_shortened_in_messages() {
    let word = "x".repeat(1000);
    let (_, problem) = line_error(&format!("start 0 0 0\n{word} 1 2"));
    let LineProblem::UnknownKeyword(quoted) = problem else {
        panic!("{problem:?}");
    };
    assert_eq!(quoted.chars().count(), QUOTE_CHARS + 1);
}

#[test]
fn every_builtin_exists_starts_on_free_floor_and_round_trips() {
    for name in WorldFile::BUILTIN_NAMES {
        let f = WorldFile::builtin(name).unwrap();
        assert!(!f.name.is_empty() && !f.world.walls().is_empty());
        // The start keeps the XR4000's radius (0.32 m) from every wall.
        let p = [f.start.x, f.start.y];
        let clearance = f
            .world
            .walls()
            .iter()
            .map(|&[a, b]| {
                let e = [b[0] - a[0], b[1] - a[1]];
                let t = (((p[0] - a[0]) * e[0] + (p[1] - a[1]) * e[1])
                    / (e[0] * e[0] + e[1] * e[1]))
                    .clamp(0.0, 1.0);
                (p[0] - a[0] - t * e[0]).hypot(p[1] - a[1] - t * e[1])
            })
            .fold(f64::INFINITY, f64::min);
        assert!(clearance >= 0.32, "{name}: start {clearance} m from a wall");
        let back = WorldFile::parse(&f.to_text()).unwrap();
        assert_eq!(back.world.walls(), f.world.walls(), "{name}");
        assert_eq!(back.name, f.name);
        assert!((back.start.x, back.start.y) == (f.start.x, f.start.y));
        assert!((back.start.theta - f.start.theta).abs() < 1e-12);
    }
    assert!(WorldFile::builtin("Lab").is_none());
    assert!(WorldFile::builtin("").is_none());
}

#[test]
fn the_lab_file_is_the_builtin_lab() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/lab.world");
    let file = WorldFile::load(&path).unwrap();
    let builtin = WorldFile::builtin("lab").unwrap();
    assert_eq!(file.name, builtin.name);
    assert_eq!(file.start, builtin.start);
    // Same statements, same arithmetic: the walls agree bit for bit.
    assert_eq!(file.world.walls(), builtin.world.walls());
}

#[test]
fn a_missing_file_is_an_io_error_naming_the_path() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/no-such.world");
    let err = WorldFile::load(&path).unwrap_err();
    assert!(matches!(&err, WorldFileError::Io { path: p, .. } if *p == path));
    assert!(err.to_string().contains("no-such.world"), "{err}");
}

#[test]
fn names_with_quotes_and_control_characters_round_trip() {
    let mut f = WorldFile::builtin("loop").unwrap();
    f.name = "a \"lab\" # not a comment \\ \n second line\r\tend".into();
    let back = WorldFile::parse(&f.to_text()).unwrap();
    assert_eq!(back.name, f.name);
}

/// Text made of world-file words, numbers and punctuation, so random
/// input reaches the number and geometry checks, not only the keyword
/// check.
fn world_ish_text() -> impl Strategy<Value = String> {
    let token = prop_oneof![
        Just("name".to_string()),
        Just("start".to_string()),
        Just("wall".to_string()),
        Just("polyline".to_string()),
        Just("open".to_string()),
        Just("closed".to_string()),
        Just("box".to_string()),
        Just("#".to_string()),
        Just("\"".to_string()),
        Just("\\".to_string()),
        Just("NaN".to_string()),
        Just("-inf".to_string()),
        Just("1e308".to_string()),
        Just("-0".to_string()),
        (-3.0f64..3.0).prop_map(|v| v.to_string()),
        (-2000.0f64..2000.0).prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| v.to_string()),
        "[a-z\"#\\\\]{1,4}",
    ];
    let line = proptest::collection::vec(token, 0..12).prop_map(|t| t.join(" "));
    proptest::collection::vec(line, 0..20).prop_map(|l| l.join("\n"))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_text_never_panics(text in any::<String>()) {
        let _ = WorldFile::parse(&text);
    }

    #[test]
    fn random_world_lines_never_panic_and_accepted_worlds_are_valid(
        text in world_ish_text(),
    ) {
        if let Ok(f) = WorldFile::parse(&text) {
            prop_assert!(!f.world.walls().is_empty());
            prop_assert!(f.start.x.is_finite() && f.start.y.is_finite());
            for [a, b] in f.world.walls() {
                prop_assert!((b[0] - a[0]).hypot(b[1] - a[1]) >= MIN_WALL_LENGTH);
            }
        }
    }

    #[test]
    fn to_text_then_parse_gives_the_same_walls(
        walls in proptest::collection::vec(
            // Within the 1 km a world may span.
            (-450.0f64..450.0, -450.0f64..450.0, -1.0f64..1.0, -1.0f64..1.0),
            1..40,
        ),
        heading in -180.0f64..180.0,
        name in "[ -~]{0,20}",
    ) {
        let world = World::from_segments(
            walls
                .iter()
                .filter(|w| w.2.hypot(w.3) >= 0.01)
                .map(|&(x, y, dx, dy)| [[x, y], [x + dx, y + dy]]),
        );
        prop_assume!(!world.walls().is_empty());
        let [a, _] = world.walls()[0];
        let f = WorldFile { name, world, start: Pose2::new(a[0], a[1], heading.to_radians()) };
        let back = WorldFile::parse(&f.to_text()).unwrap();
        prop_assert_eq!(back.world.walls(), f.world.walls());
        prop_assert_eq!(&back.name, &f.name);
        prop_assert!((back.start.theta - f.start.theta).abs() < 1e-12);
    }
}
