//! The CLS map on disk: versioned `map.json` mirroring the CLSM_Item list.
//!
//! ```json
//! {"format":"clsmap-cls","version":1,"frame":"map","created_by":"clsmap 0.1.0",
//!  "checksum":123456789,
//!  "segments":[{"index":0,"next":1,"mode":"actual","theta":0.0,"sigma_theta":0.002,
//!               "xc":1.0,"yc":0.0,"sigma_c":0.005,"start":[0.0,0.0],"end":[2.0,0.0]}, ...]}
//! ```
//!
//! Metres, radians, map frame. `checksum` is the CRC-32 (ISO-HDLC, as zip
//! and PNG) of the bytes of the `segments` array exactly as stored (written
//! as compact JSON, the last member of the file). The segments are parsed
//! from exactly the bytes the checksum covers, whatever the spelling of
//! their key, so no edit of the file can reach the map unchecked. The
//! stored bytes are checked rather than a re-serialisation of the parsed
//! numbers, because serde_json's default float parser may differ from the
//! writer by one unit in the last place, which would change the
//! re-serialised text.
//!
//! This is version 1, the CLS map alone; [`crate::map::file`] writes
//! version 2 (walls, keyframes and the pose graph too) and reads both.

use std::path::{Path, PathBuf};

use crc::{CRC_32_ISO_HDLC, Crc};
use serde::{Deserialize, Serialize};

use super::loops::{ClsLoop, ClsSegment, ClsShape, ClsmItem, InvariantError, SegmentMode};
use crate::geometry::{CogLine, SegmentId};

/// The file's `format` tag.
pub const FORMAT: &str = "clsmap-cls";
/// The only version this build reads and writes.
pub const VERSION: u32 = 1;

static CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// One CLSM_Item as stored.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentRecord {
    pub index: usize,
    pub next: usize,
    pub mode: SegmentMode,
    pub theta: f64,
    pub sigma_theta: f64,
    pub xc: f64,
    pub yc: f64,
    pub sigma_c: f64,
    pub start: [f64; 2],
    pub end: [f64; 2],
    /// The wall (id in the file's `walls`) an actual segment lies on;
    /// absent in version-1 and version-2 files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall: Option<SegmentId>,
}

/// The whole version-1 file, its segments still as the bytes stored.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile<'a> {
    format: String,
    version: u32,
    /// Frame of every coordinate; always "map".
    #[allow(dead_code)]
    frame: String,
    /// Program and version that wrote the file.
    #[allow(dead_code)]
    created_by: String,
    /// CRC-32 of the compact JSON of `segments`.
    checksum: u32,
    #[serde(borrow)]
    segments: &'a serde_json::value::RawValue,
}

/// Why a map could not be stored or loaded.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{path}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the map file is truncated: {0}")]
    Truncated(serde_json::Error),
    #[error("the map file is not valid map JSON: {0}")]
    Parse(serde_json::Error),
    #[error("not a CLS map file (format {0:?})")]
    Format(String),
    #[error("map file version {found} is not supported (this build reads 1 and 2)")]
    Version { found: u32 },
    #[error("checksum mismatch: the file says {stored:#010x}, its segments give {computed:#010x}")]
    Checksum { stored: u32, computed: u32 },
    #[error("segment {0} has a non-finite number")]
    NotFinite(usize),
    #[error(
        "segment at position {position} has index {index} or next {next} out of order or range"
    )]
    BadIndex {
        position: usize,
        index: usize,
        next: usize,
    },
    #[error("the next links starting at segment {0} do not form a closed loop")]
    BrokenLoop(usize),
    #[error("the stored map is not a valid CLS map: {0}")]
    Invariant(InvariantError),
    #[error("the stored map is inconsistent: {0}")]
    Inconsistent(String),
    #[error("cannot encode the map: {0}")]
    Encode(String),
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + '_ {
    move |source| StoreError::Io {
        path: path.to_path_buf(),
        source,
    }
}

pub(crate) fn io_error_at(path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + '_ {
    io_error(path)
}

/// A running CRC-32 of the same kind, for bytes written in pieces.
pub(crate) fn crc32_digest() -> crc::Digest<'static, u32> {
    CRC32.digest()
}

pub(crate) fn crc32(bytes: &[u8]) -> u32 {
    CRC32.checksum(bytes)
}

/// A parse error, told apart: a file cut short, or one that is not JSON of
/// the expected shape.
pub(crate) fn parse_error(e: serde_json::Error) -> StoreError {
    if e.is_eof() {
        StoreError::Truncated(e)
    } else {
        StoreError::Parse(e)
    }
}

pub(crate) fn record(item: &ClsmItem) -> SegmentRecord {
    SegmentRecord {
        index: item.index,
        next: item.next,
        mode: item.mode,
        theta: item.line.theta,
        sigma_theta: item.line.sigma_theta,
        xc: item.line.xc,
        yc: item.line.yc,
        sigma_c: item.line.sigma_c,
        start: item.line.start,
        end: item.line.end,
        wall: item.wall,
    }
}

/// The metadata members of the file; the segments follow as raw JSON.
#[derive(Serialize)]
struct Header<'a> {
    format: &'a str,
    version: u32,
    frame: &'a str,
    created_by: &'a str,
    checksum: u32,
}

/// The file contents for `items`.
pub fn encode(items: &[ClsmItem]) -> Result<String, serde_json::Error> {
    let segments: Vec<SegmentRecord> = items.iter().map(record).collect();
    let array = serde_json::to_string(&segments)?;
    let header = serde_json::to_string(&Header {
        format: FORMAT,
        version: VERSION,
        frame: "map",
        created_by: concat!("clsmap ", env!("CARGO_PKG_VERSION")),
        checksum: CRC32.checksum(array.as_bytes()),
    })?;
    // `header` is a JSON object: open it up and append the segments last.
    let open = header.strip_suffix('}').unwrap_or(&header);
    Ok(format!("{open},\n\"segments\":{array}}}\n"))
}

/// Writes `items` to `path` atomically as version 1 (what builds before
/// version 2 wrote; kept so such files can be made for tests).
pub fn save_items(path: &Path, items: &[ClsmItem]) -> Result<(), StoreError> {
    let text = encode(items).map_err(StoreError::Parse)?;
    crate::files::durable::write_atomically(path, text.as_bytes()).map_err(io_error(path))
}

/// Whether a map file's checksum is checked when it is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ChecksumCheck {
    /// A mismatch refuses the file: a damaged or edited map is never used
    /// unknowingly.
    #[default]
    Verify,
    /// A mismatch is reported (see [`ChecksumMismatch`]) and the file is
    /// read if it is otherwise valid: for a map edited by hand. Every other
    /// check (format, finite numbers, links, invariants) still applies.
    Ignore,
}

impl ChecksumCheck {
    /// [`Ignore`](Self::Ignore) when `ignore` (an `--ignore-checksum`
    /// flag or setting), else [`Verify`](Self::Verify).
    pub fn ignoring(ignore: bool) -> Self {
        if ignore {
            ChecksumCheck::Ignore
        } else {
            ChecksumCheck::Verify
        }
    }
}

/// A checksum that did not match, let through by [`ChecksumCheck::Ignore`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChecksumMismatch {
    pub stored: u32,
    pub computed: u32,
}

/// `Ok(None)` when `stored` matches `bytes`, the mismatch when `check`
/// lets it through, else [`StoreError::Checksum`].
pub(crate) fn check_checksum(
    bytes: &[u8],
    stored: u32,
    check: ChecksumCheck,
) -> Result<Option<ChecksumMismatch>, StoreError> {
    let computed = crc32(bytes);
    match (computed == stored, check) {
        (true, _) => Ok(None),
        (false, ChecksumCheck::Ignore) => Ok(Some(ChecksumMismatch { stored, computed })),
        (false, ChecksumCheck::Verify) => Err(StoreError::Checksum { stored, computed }),
    }
}

/// Parses and validates the contents of a version-1 map file.
pub fn decode(text: &str) -> Result<Vec<ClsShape>, StoreError> {
    decode_with(text, ChecksumCheck::Verify).map(|(shapes, _)| shapes)
}

/// [`decode`], with the checksum checked as `check` says; also returns a
/// mismatch that was let through.
pub fn decode_with(
    text: &str,
    check: ChecksumCheck,
) -> Result<(Vec<ClsShape>, Option<ChecksumMismatch>), StoreError> {
    let file: MapFile<'_> = serde_json::from_str(text).map_err(parse_error)?;
    if file.format != FORMAT {
        return Err(StoreError::Format(file.format));
    }
    if file.version != VERSION {
        return Err(StoreError::Version {
            found: file.version,
        });
    }
    let raw = file.segments.get();
    let mismatch = check_checksum(raw.as_bytes(), file.checksum, check)?;
    let segments: Vec<SegmentRecord> = serde_json::from_str(raw).map_err(parse_error)?;
    Ok((shapes_from_checked_records(&segments)?, mismatch))
}

/// Checks `segments` (finite, indices in order, links in range) and
/// follows them into shapes.
pub(crate) fn shapes_from_checked_records(
    segments: &[SegmentRecord],
) -> Result<Vec<ClsShape>, StoreError> {
    let n = segments.len();
    for (position, s) in segments.iter().enumerate() {
        let numbers = [
            s.theta,
            s.sigma_theta,
            s.xc,
            s.yc,
            s.sigma_c,
            s.start[0],
            s.start[1],
            s.end[0],
            s.end[1],
        ];
        if !numbers.iter().all(|v| v.is_finite()) {
            return Err(StoreError::NotFinite(position));
        }
        if s.index != position || s.next >= n {
            return Err(StoreError::BadIndex {
                position,
                index: s.index,
                next: s.next,
            });
        }
    }
    shapes_from_records(segments)
}

/// Follows the `next` links into loops, then groups holes (clockwise)
/// with the outer loop (counter-clockwise) that encloses them.
/// A loop with its position in the file, for error messages.
type IndexedLoop = (usize, ClsLoop);

fn shapes_from_records(records: &[SegmentRecord]) -> Result<Vec<ClsShape>, StoreError> {
    let n = records.len();
    let mut seen = vec![false; n];
    let mut loops = Vec::new();
    for first in 0..n {
        if seen[first] {
            continue;
        }
        let mut segments = Vec::new();
        let mut k = first;
        loop {
            if seen[k] {
                return Err(StoreError::BrokenLoop(first));
            }
            seen[k] = true;
            let r = &records[k];
            let line = CogLine {
                theta: r.theta,
                xc: r.xc,
                yc: r.yc,
                sigma_theta: r.sigma_theta,
                sigma_c: r.sigma_c,
                start: r.start,
                end: r.end,
                n_points: 0,
                wall_ends: crate::geometry::WallEnds::NONE,
            };
            // Only a piece of a wall names one.
            let wall = r.wall.filter(|_| r.mode == SegmentMode::Actual);
            segments.push(ClsSegment {
                line,
                mode: r.mode,
                wall,
            });
            k = r.next;
            if k == first {
                break;
            }
        }
        loops.push(ClsLoop::new(segments));
    }
    // A loop enclosing no area is neither an outline nor a hole.
    if let Some((index, l)) = loops
        .iter()
        .enumerate()
        .find(|(_, l)| l.signed_area().is_nan() || l.signed_area() == 0.0)
    {
        return Err(StoreError::Invariant(InvariantError::Orientation {
            loop_index: index,
            signed_area: l.signed_area(),
            expected: "a loop must enclose some area",
        }));
    }
    let (outers, holes): (Vec<IndexedLoop>, Vec<IndexedLoop>) = loops
        .into_iter()
        .enumerate()
        .partition(|(_, l)| l.signed_area() > 0.0);
    let mut shapes: Vec<ClsShape> = outers
        .into_iter()
        .map(|(_, outer)| ClsShape {
            outer,
            holes: vec![],
        })
        .collect();
    for (index, hole) in holes {
        let probe = hole.segments().first().map(|s| s.point_on_left(1e-6));
        // The smallest outer loop around the hole is its shape.
        let owner = probe.and_then(|p| {
            shapes
                .iter_mut()
                .filter(|s| s.outer.encloses(p))
                .min_by(|a, b| a.outer.signed_area().total_cmp(&b.outer.signed_area()))
        });
        match owner {
            Some(shape) => shape.holes.push(hole),
            None => {
                return Err(StoreError::Invariant(InvariantError::Orientation {
                    loop_index: index,
                    signed_area: hole.signed_area(),
                    expected: "a clockwise loop must lie inside a counter-clockwise one",
                }));
            }
        }
    }
    Ok(shapes)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::map::cls::loops::items;

    fn square_shape() -> Vec<ClsShape> {
        let pts = [[0.0, 0.0], [3.0, 0.0], [3.0, 2.0], [0.0, 2.0]];
        let outer = ClsLoop::new(
            (0..4)
                .map(|i| ClsSegment::virtual_between(pts[i], pts[(i + 1) % 4]))
                .collect(),
        );
        let hole_pts = [[1.0, 0.5], [1.0, 1.5], [2.0, 1.5], [2.0, 0.5]];
        let hole = ClsLoop::new(
            (0..4)
                .map(|i| {
                    let mut s = ClsSegment::virtual_between(hole_pts[i], hole_pts[(i + 1) % 4]);
                    s.mode = SegmentMode::Actual;
                    s.line.sigma_c = 0.01;
                    s
                })
                .collect(),
        );
        vec![ClsShape {
            outer,
            holes: vec![hole],
        }]
    }

    #[test]
    fn round_trips_and_regroups_holes() {
        let shapes = square_shape();
        let text = encode(&items(&shapes)).unwrap();
        let back = decode(&text).unwrap();
        assert_eq!(back.len(), 1);
        assert_eq!(back[0].holes.len(), 1);
        assert_eq!(items(&back).len(), 8);
        for (a, b) in items(&back).iter().zip(items(&shapes)) {
            assert_eq!(a.line.start, b.line.start);
            assert_eq!(a.mode, b.mode);
            assert_eq!(a.line.sigma_c, b.line.sigma_c);
        }
    }

    #[test]
    fn corrupt_files_are_refused_with_the_reason() {
        let text = encode(&items(&square_shape())).unwrap();
        assert!(matches!(
            decode(&text[..text.len() / 2]),
            Err(StoreError::Truncated(_))
        ));
        let flipped = text.replacen("3.0", "3.5", 1);
        assert!(matches!(decode(&flipped), Err(StoreError::Checksum { .. })));
        let v2 = text.replacen("\"version\":1", "\"version\":2", 1);
        assert!(matches!(decode(&v2), Err(StoreError::Version { found: 2 })));
        assert!(matches!(decode("{\"x\": 1}"), Err(StoreError::Parse(_))));
        // Bad links behind a valid checksum.
        let relink = |position: usize, next: usize| {
            let mut items_back: Vec<ClsmItem> = items(&square_shape());
            items_back[position].next = next;
            encode(&items_back).unwrap()
        };
        assert!(matches!(
            decode(&relink(3, 99)),
            Err(StoreError::BadIndex { position: 3, .. })
        ));
        assert!(matches!(
            decode(&relink(3, 1)),
            Err(StoreError::BrokenLoop(0))
        ));
        let nan = text.replacen("\"theta\":", "\"theta\":1e999,\"x\":", 1);
        assert!(decode(&nan).is_err());
    }

    #[test]
    fn a_loop_enclosing_no_area_is_refused_by_its_index() {
        let mut shapes = square_shape();
        // A second shape whose outline goes out and back along one line.
        let flat = ClsLoop::new(vec![
            ClsSegment::virtual_between([5.0, 0.0], [6.0, 0.0]),
            ClsSegment::virtual_between([6.0, 0.0], [5.0, 0.0]),
        ]);
        shapes.push(ClsShape {
            outer: flat,
            holes: vec![],
        });
        let text = encode(&items(&shapes)).unwrap();
        match decode(&text) {
            Err(StoreError::Invariant(InvariantError::Orientation { loop_index, .. })) => {
                assert_eq!(loop_index, 2)
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn an_escaped_key_cannot_carry_unchecked_segments() {
        let text = encode(&items(&square_shape())).unwrap();
        // Edited coordinates under a zero checksum and an escaped key: the
        // bytes parsed are the bytes checked, so this is a mismatch.
        let forged = text
            .replacen("3.0", "9.0", 1)
            .replace("\"segments\"", "\"segm\\u0065nts\"");
        let forged = regex_free_checksum_zero(&forged);
        assert!(
            matches!(decode(&forged), Err(StoreError::Checksum { stored: 0, .. })),
            "{:?}",
            decode(&forged)
        );
        // A second segments member is refused, not silently chosen.
        let twice = text.replacen("\"frame\"", "\"segments\":[],\"frame\"", 1);
        assert!(decode(&twice).is_err());
    }

    /// `text` with its checksum value replaced by 0.
    fn regex_free_checksum_zero(text: &str) -> String {
        let at = text.find("\"checksum\":").unwrap() + "\"checksum\":".len();
        let end = at + text[at..].find(',').unwrap();
        format!("{}0{}", &text[..at], &text[end..])
    }

    #[test]
    fn saving_is_atomic_and_leaves_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("clsmap-store-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("map.json");
        save_items(&path, &items(&square_shape())).unwrap();
        save_items(&path, &items(&square_shape())).unwrap();
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(decode(&text).unwrap().len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
