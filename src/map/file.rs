//! `map.json`, version 3: everything a map is made of, in one file.
//!
//! ```json
//! {"format":"clsmap-map","version":3,"frame":"map","created_by":"clsmap 0.1.0",
//!  "payload":{"segments":[...],"walls":[...],"keyframes":[...],"edges":[...]},
//!  "checksum":123456789}
//! ```
//!
//! - `segments`: the CLS map's CLSM_Item list, as in version 1; a wall
//!   piece also names the wall it lies on (`wall`, an id in `walls`).
//!   That is all version 3 adds to version 2, whose files still load
//!   (their pieces name no wall).
//! - `walls`: the fused wall segments local localization matched against
//!   (`id`, `observations`, `line`); what `segments.json` held before.
//! - `keyframes`: per keyframe its time, pose, pose covariance, path
//!   length, lines and local CLS region (robot frame): the source the
//!   walls and the CLS map are rebuilt from.
//! - `edges`: the pose graph over the keyframes (chain and loop edges,
//!   measurement and information), so loops close against a loaded map.
//!
//! Metres, radians, map frame. `checksum` is the CRC-32 of the bytes of
//! `payload` exactly as stored; the payload is parsed from exactly those
//! bytes, so no edit reaches the map unchecked. It comes last so the
//! payload streams to the file as it is serialised (a large map is never
//! held as text in memory). Files are written atomically (see
//! [`crate::files::durable`]). Version 1 files (the CLS map only)
//! still load, with no walls or keyframes.

use std::io::Write as _;
use std::path::Path;
use std::sync::Arc;

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use super::cls::loops::ClsmItem;
use super::cls::store::{
    self, SegmentRecord, StoreError, check_checksum, crc32_digest, io_error_at, parse_error,
    record, shapes_from_checked_records,
};
pub use super::cls::store::{ChecksumCheck, ChecksumMismatch};
use super::cls::{ClsMap, ClsMapConfig, LocalEdge, LocalRegion, LocalSource};
use super::{Edge, EdgeKind};
use super::{Keyframe, MapSegment};
use crate::geometry::{CogLine, Pose2};

/// The file's `format` tag.
pub const FORMAT: &str = "clsmap-map";
/// The version this build writes.
pub const VERSION: u32 = 3;
/// The version before wall pieces named their walls; read as well.
const VERSION_2: u32 = 2;

/// One keyframe as stored.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyframeRecord {
    t: f64,
    pose: Pose2,
    covariance: [[f64; 3]; 3],
    travelled: f64,
    lines: Vec<CogLine>,
    region: Option<RegionRecord>,
}

/// The same, borrowed from a keyframe for writing (a checkpoint of a
/// large map copies no scan).
#[derive(Serialize)]
struct KeyframeView<'a> {
    t: f64,
    pose: &'a Pose2,
    covariance: &'a [[f64; 3]; 3],
    travelled: f64,
    lines: &'a [CogLine],
    region: Option<RegionView<'a>>,
}

/// [`RegionRecord`] borrowed: vertices and line indices straight from the
/// region's edges.
struct RegionView<'a>(&'a LocalRegion);

impl Serialize for RegionView<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        struct Points<'a>(&'a LocalRegion);
        impl Serialize for Points<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.collect_seq(self.0.edges.iter().map(|e| e.start))
            }
        }
        struct Lines<'a>(&'a LocalRegion);
        impl Serialize for Lines<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.collect_seq(self.0.edges.iter().map(|e| match e.source {
                    LocalSource::Actual(i) => Some(i),
                    LocalSource::Virtual => None,
                }))
            }
        }
        let mut st = serializer.serialize_struct("RegionRecord", 2)?;
        st.serialize_field("points", &Points(self.0))?;
        st.serialize_field("lines", &Lines(self.0))?;
        st.end()
    }
}

/// A local region as its closed polygon: vertex `i` starts edge `i`, and
/// `lines[i]` is the scan line edge `i` lies on (`null` for a virtual
/// edge). Half the size of edges with both ends, for the same polygon.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct RegionRecord {
    points: Vec<[f64; 2]>,
    lines: Vec<Option<usize>>,
}

impl RegionRecord {
    fn region(&self) -> LocalRegion {
        let n = self.points.len();
        LocalRegion {
            edges: (0..n)
                .map(|i| LocalEdge {
                    start: self.points[i],
                    end: self.points[(i + 1) % n],
                    source: self
                        .lines
                        .get(i)
                        .copied()
                        .flatten()
                        .map_or(LocalSource::Virtual, LocalSource::Actual),
                })
                .collect(),
        }
    }
}

/// One pose-graph edge as stored.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct EdgeRecord {
    from: usize,
    to: usize,
    kind: EdgeKind,
    measurement: Pose2,
    information: [[f64; 3]; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Payload {
    segments: Vec<SegmentRecord>,
    walls: Vec<MapSegment>,
    keyframes: Vec<KeyframeRecord>,
    edges: Vec<EdgeRecord>,
}

/// [`Payload`] borrowed from a map's contents, for writing.
#[derive(Serialize)]
struct PayloadView<'a> {
    segments: Vec<SegmentRecord>,
    walls: &'a [MapSegment],
    keyframes: Vec<KeyframeView<'a>>,
    edges: Vec<EdgeRecord>,
}

#[derive(Serialize)]
struct Header<'a> {
    format: &'a str,
    version: u32,
    frame: &'a str,
    created_by: &'a str,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Envelope<'a> {
    format: String,
    #[allow(dead_code)]
    version: u32,
    #[allow(dead_code)]
    frame: String,
    #[allow(dead_code)]
    created_by: String,
    checksum: u32,
    #[serde(borrow)]
    payload: &'a serde_json::value::RawValue,
}

/// Just enough of either version to tell which it is.
#[derive(Deserialize)]
struct Probe {
    format: String,
    version: u32,
}

/// What a map is made of: the CLS map, the walls, and the keyframes with
/// their poses and the pose graph's edges. Keyframes are shared, not
/// copied, so a snapshot of a running map is cheap. The walls and the CLS
/// map are derived data: a rebuild from the keyframes at their poses gives
/// them again.
#[derive(Debug, Clone, Default)]
pub struct MapContents {
    pub cls: ClsMap,
    pub walls: Vec<MapSegment>,
    pub keyframes: Vec<Arc<Keyframe>>,
    pub poses: Vec<Pose2>,
    pub edges: Vec<Edge>,
}

/// A map file read back, and which version it was.
#[derive(Debug, Clone)]
pub struct LoadedMap {
    pub contents: MapContents,
    pub version: u32,
    /// The checksum did not match and [`ChecksumCheck::Ignore`] let the
    /// file through (a warning names the file when it is read by path).
    pub checksum_mismatch: Option<ChecksumMismatch>,
}

fn matrix(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// Whether every number `contents` would store is finite: JSON has no
/// NaN (serde writes `null`), and a map that saves must load.
fn storable(contents: &MapContents) -> Result<(), String> {
    if let Some(i) = contents
        .walls
        .iter()
        .position(|w| !all_finite(line_numbers(&w.line)))
    {
        return Err(format!("wall {i} has a non-finite number"));
    }
    for (i, (k, p)) in contents.keyframes.iter().zip(&contents.poses).enumerate() {
        let numbers = [k.t, k.travelled, p.x, p.y, p.theta]
            .into_iter()
            .chain(k.covariance.iter().flatten().copied())
            .chain(k.lines.iter().flat_map(line_numbers))
            .chain(
                k.region
                    .iter()
                    .flat_map(|r| &r.edges)
                    .flat_map(|e| [e.start[0], e.start[1]]),
            );
        if !all_finite(numbers) {
            return Err(format!("keyframe {i} has a non-finite number"));
        }
    }
    if let Some(i) = contents.edges.iter().position(|e| {
        !all_finite([e.measurement.x, e.measurement.y, e.measurement.theta])
            || !e.information.iter().all(|v| v.is_finite())
    }) {
        return Err(format!("edge {i} has a non-finite number"));
    }
    Ok(())
}

/// The payload of `contents` as stored, compact JSON, into `out`.
fn write_payload(out: &mut impl std::io::Write, contents: &MapContents) -> std::io::Result<()> {
    storable(contents).map_err(|why| {
        std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not saved: {why}"))
    })?;
    let items: Vec<ClsmItem> = contents.cls.items();
    let payload = PayloadView {
        segments: items.iter().map(record).collect(),
        walls: &contents.walls,
        keyframes: contents
            .keyframes
            .iter()
            .zip(&contents.poses)
            .map(|(k, pose)| KeyframeView {
                t: k.t,
                pose,
                covariance: &k.covariance,
                travelled: k.travelled,
                lines: &k.lines,
                region: k.region.as_ref().map(RegionView),
            })
            .collect(),
        edges: contents
            .edges
            .iter()
            .map(|e| EdgeRecord {
                from: e.from,
                to: e.to,
                kind: e.kind,
                measurement: e.measurement,
                information: matrix(&e.information),
            })
            .collect(),
    };
    serde_json::to_writer(out, &payload).map_err(std::io::Error::other)
}

/// The file's first part, up to the payload.
fn header_bytes() -> Result<Vec<u8>, serde_json::Error> {
    let header = serde_json::to_string(&Header {
        format: FORMAT,
        version: VERSION,
        frame: "map",
        created_by: concat!("clsmap ", env!("CARGO_PKG_VERSION")),
    })?;
    // `header` is a JSON object: open it up for the payload.
    let open = header.strip_suffix('}').unwrap_or(&header);
    Ok(format!("{open},\n\"payload\":").into_bytes())
}

/// Passes bytes on and keeps their CRC-32.
struct Checksummed<W> {
    inner: W,
    digest: crc::Digest<'static, u32>,
}

impl<W: std::io::Write> std::io::Write for Checksummed<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.digest.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Writes the whole file for `contents` to `out`.
fn write_file(out: &mut dyn std::io::Write, contents: &MapContents) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(out);
    out.write_all(&header_bytes()?)?;
    let mut payload = Checksummed {
        inner: &mut out,
        digest: crc32_digest(),
    };
    write_payload(&mut payload, contents)?;
    let checksum = payload.digest.finalize();
    write!(out, ",\n\"checksum\":{checksum}}}\n")?;
    out.flush()
}

/// The file text for `contents`.
pub fn encode(contents: &MapContents) -> Result<String, StoreError> {
    let mut text = Vec::new();
    write_file(&mut text, contents).map_err(|e| StoreError::Encode(e.to_string()))?;
    String::from_utf8(text).map_err(|e| StoreError::Encode(e.to_string()))
}

/// Writes `contents` to `path` atomically.
pub fn save(path: &Path, contents: &MapContents) -> Result<(), StoreError> {
    crate::files::durable::write_atomically_with(path, |out| write_file(out, contents))
        .map_err(io_error_at(path))
}

/// Reads a map file of either version; a corrupt, truncated, foreign or
/// inconsistent file is refused with the reason.
pub fn load(path: &Path) -> Result<LoadedMap, StoreError> {
    load_with(path, ChecksumCheck::Verify)
}

/// [`load`], with the checksum checked as `check` says; a mismatch let
/// through is logged as a warning naming the file.
pub fn load_with(path: &Path, check: ChecksumCheck) -> Result<LoadedMap, StoreError> {
    let text = crate::files::durable::read_bounded(path, crate::files::durable::MAX_MAP_BYTES)
        .map_err(io_error_at(path))?;
    let loaded = decode_with(&text, check)?;
    if let Some(m) = loaded.checksum_mismatch {
        tracing::warn!(
            map = %path.display(),
            "checksum mismatch ignored (the file says {:#010x}, its contents give {:#010x}): \
             the map was changed since it was written",
            m.stored,
            m.computed
        );
    }
    Ok(loaded)
}

/// Parses and validates the contents of a map file of either version.
pub fn decode(text: &str) -> Result<LoadedMap, StoreError> {
    decode_with(text, ChecksumCheck::Verify)
}

/// [`decode`], with the checksum checked as `check` says.
pub fn decode_with(text: &str, check: ChecksumCheck) -> Result<LoadedMap, StoreError> {
    let probe: Probe = serde_json::from_str(text).map_err(parse_error)?;
    if probe.format == store::FORMAT && probe.version == store::VERSION {
        let (shapes, checksum_mismatch) = store::decode_with(text, check)?;
        return Ok(LoadedMap {
            contents: MapContents {
                cls: ClsMap::from_shapes(ClsMapConfig::default(), shapes)
                    .map_err(StoreError::Invariant)?,
                ..MapContents::default()
            },
            version: store::VERSION,
            checksum_mismatch,
        });
    }
    if probe.format != FORMAT && probe.format != store::FORMAT {
        return Err(StoreError::Format(probe.format));
    }
    if probe.version != VERSION && probe.version != VERSION_2 {
        return Err(StoreError::Version {
            found: probe.version,
        });
    }
    let file: Envelope<'_> = serde_json::from_str(text).map_err(parse_error)?;
    if file.format != FORMAT {
        return Err(StoreError::Format(file.format));
    }
    let raw = file.payload.get();
    let checksum_mismatch = check_checksum(raw.as_bytes(), file.checksum, check)?;
    let payload: Payload = serde_json::from_str(raw).map_err(parse_error)?;
    let shapes = shapes_from_checked_records(&payload.segments)?;
    let cls =
        ClsMap::from_shapes(ClsMapConfig::default(), shapes).map_err(StoreError::Invariant)?;
    let contents = checked_contents(cls, payload)?;
    Ok(LoadedMap {
        contents,
        version: probe.version,
        checksum_mismatch,
    })
}

fn all_finite(values: impl IntoIterator<Item = f64>) -> bool {
    values.into_iter().all(f64::is_finite)
}

fn line_numbers(l: &CogLine) -> [f64; 9] {
    [
        l.theta,
        l.xc,
        l.yc,
        l.sigma_theta,
        l.sigma_c,
        l.start[0],
        l.start[1],
        l.end[0],
        l.end[1],
    ]
}

fn inconsistent(what: String) -> StoreError {
    StoreError::Inconsistent(what)
}

/// The payload's walls, keyframes and edges, checked: finite numbers,
/// distinct wall ids, edges between stored keyframes with a positive
/// semi-definite information matrix.
fn checked_contents(cls: ClsMap, payload: Payload) -> Result<MapContents, StoreError> {
    let mut ids = std::collections::HashSet::new();
    // Ids index memory on load: a few per wall (ids of bridged walls stay
    // free), never millions more than there are walls.
    let max_id = 16 * payload.walls.len() as u64 + 1024;
    for (i, w) in payload.walls.iter().enumerate() {
        if u64::from(w.id.0) > max_id {
            return Err(inconsistent(format!(
                "wall {i}'s id {} is far beyond the {} walls stored",
                w.id.0,
                payload.walls.len()
            )));
        }
        if !all_finite(line_numbers(&w.line)) {
            return Err(inconsistent(format!("wall {i} has a non-finite number")));
        }
        if !ids.insert(w.id) {
            return Err(inconsistent(format!("wall id {} appears twice", w.id.0)));
        }
    }
    if let Some((i, wall)) = payload
        .segments
        .iter()
        .enumerate()
        .find_map(|(i, r)| r.wall.filter(|w| !ids.contains(w)).map(|w| (i, w)))
    {
        return Err(inconsistent(format!(
            "segment {i} lies on wall {}, which the file does not hold",
            wall.0
        )));
    }
    let n = payload.keyframes.len();
    let mut keyframes = Vec::with_capacity(n);
    let mut poses = Vec::with_capacity(n);
    for (i, k) in payload.keyframes.into_iter().enumerate() {
        let numbers = [k.t, k.travelled, k.pose.x, k.pose.y, k.pose.theta]
            .into_iter()
            .chain(k.covariance.iter().flatten().copied())
            .chain(k.lines.iter().flat_map(line_numbers))
            .chain(k.region.iter().flat_map(|r| &r.points).flatten().copied());
        if !all_finite(numbers) {
            return Err(inconsistent(format!(
                "keyframe {i} has a non-finite number"
            )));
        }
        let lines = k.lines.len();
        let bad_region = k.region.as_ref().is_some_and(|r| {
            r.lines.len() != r.points.len() || r.lines.iter().flatten().any(|&j| j >= lines)
        });
        if bad_region {
            return Err(inconsistent(format!(
                "keyframe {i}'s region does not fit its lines"
            )));
        }
        poses.push(k.pose);
        keyframes.push(Arc::new(Keyframe {
            t: k.t,
            region: k.region.as_ref().map(RegionRecord::region),
            lines: k.lines,
            covariance: k.covariance,
            travelled: k.travelled,
        }));
    }
    let mut edges = Vec::with_capacity(payload.edges.len());
    for (i, e) in payload.edges.iter().enumerate() {
        let numbers = [e.measurement.x, e.measurement.y, e.measurement.theta]
            .into_iter()
            .chain(e.information.iter().flatten().copied());
        if !all_finite(numbers) {
            return Err(inconsistent(format!("edge {i} has a non-finite number")));
        }
        if e.from >= n || e.to >= n || e.from == e.to {
            return Err(inconsistent(format!(
                "edge {i} joins keyframes {} and {} of {n}",
                e.from, e.to
            )));
        }
        let information = Matrix3::from_fn(|r, c| e.information[r][c]);
        let symmetric = (information - information.transpose()).abs().max()
            <= 1e-9 * information.abs().max().max(1.0);
        let semi_definite = information
            .symmetric_eigen()
            .eigenvalues
            .iter()
            .all(|&v| v >= -1e-9 * information.abs().max().max(1.0));
        if !(symmetric && semi_definite) {
            return Err(inconsistent(format!(
                "edge {i}'s information is not symmetric positive semi-definite"
            )));
        }
        edges.push(Edge {
            from: e.from,
            to: e.to,
            measurement: e.measurement,
            information,
            kind: e.kind,
        });
    }
    Ok(MapContents {
        cls,
        walls: payload.walls,
        keyframes,
        poses,
        edges,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::map::cls::loops::items;
    use crate::map::cls::store::crc32;
    use crate::map::cls::{ClsLoop, ClsSegment, ClsShape};

    /// The wall the square's first side lies on, id 3 in [`contents`].
    fn bottom_wall() -> CogLine {
        CogLine::from_centre(0.0, [1.5, 0.0], -1.5, 1.5, 0.005, 0.002, 40)
    }

    fn square() -> ClsMap {
        let pts = [[0.0, 0.0], [3.0, 0.0], [3.0, 2.0], [0.0, 2.0]];
        let outer = ClsLoop::new(
            (0..4)
                .map(|i| match i {
                    // As stored: a piece's point count is not kept.
                    0 => ClsSegment::actual_on(
                        &CogLine {
                            n_points: 0,
                            ..bottom_wall()
                        },
                        Some(crate::geometry::SegmentId(3)),
                        pts[0],
                        pts[1],
                    ),
                    _ => ClsSegment::virtual_between(pts[i], pts[(i + 1) % 4]),
                })
                .collect(),
        );
        let shapes = vec![ClsShape {
            outer,
            holes: vec![],
        }];
        ClsMap::from_shapes(ClsMapConfig::default(), shapes).unwrap()
    }

    fn contents() -> MapContents {
        let wall = bottom_wall();
        let keyframe = |t: f64| Keyframe {
            t,
            lines: vec![wall],
            region: Some(LocalRegion {
                edges: vec![
                    LocalEdge {
                        start: [0.0, 0.0],
                        end: [1.0, 0.0],
                        source: LocalSource::Actual(0),
                    },
                    LocalEdge {
                        start: [1.0, 0.0],
                        end: [0.0, 1.0],
                        source: LocalSource::Virtual,
                    },
                    LocalEdge {
                        start: [0.0, 1.0],
                        end: [0.0, 0.0],
                        source: LocalSource::Virtual,
                    },
                ],
            }),
            covariance: [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-5]],
            travelled: t * 0.5,
        };
        MapContents {
            cls: square(),
            walls: vec![MapSegment {
                id: crate::geometry::SegmentId(3),
                observations: 2,
                line: wall,
            }],
            keyframes: vec![Arc::new(keyframe(0.0)), Arc::new(keyframe(1.0))],
            poses: vec![Pose2::IDENTITY, Pose2::new(0.5, 0.0, 0.1)],
            edges: vec![Edge {
                from: 0,
                to: 1,
                measurement: Pose2::new(0.5, 0.0, 0.1),
                // σ 1 cm and 2 mrad.
                information: nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(
                    1e4, 1e4, 2.5e5,
                )),
                kind: EdgeKind::Chain,
            }],
        }
    }

    #[test]
    fn version_3_round_trips_every_part() {
        let c = contents();
        let back = decode(&encode(&c).unwrap()).unwrap();
        assert_eq!(back.version, 3);
        assert_eq!(back.contents.cls.items(), c.cls.items());
        assert_eq!(
            back.contents.cls.actual_segments().next().unwrap().wall,
            Some(crate::geometry::SegmentId(3))
        );
        assert_eq!(back.contents.walls, c.walls);
        assert_eq!(back.contents.poses, c.poses);
        assert_eq!(back.contents.edges, c.edges);
        assert_eq!(*back.contents.keyframes[1], *c.keyframes[1]);
    }

    #[test]
    fn version_2_files_load_with_wall_pieces_naming_no_wall() {
        let text = encode(&contents()).unwrap();
        let raw = payload_of(&text).replacen(",\"wall\":3", "", 1);
        let v2 = with_payload(&raw).replacen("\"version\":3", "\"version\":2", 1);
        let back = decode(&v2).unwrap();
        assert_eq!(back.version, 2);
        let piece = back.contents.cls.actual_segments().next().unwrap();
        assert_eq!(
            (piece.wall, piece.line),
            (None, contents().cls.actual_segments().next().unwrap().line)
        );
        assert_eq!(back.contents.walls, contents().walls);
    }

    #[test]
    fn a_wall_piece_naming_a_wall_the_file_lacks_is_refused() {
        let text = encode(&contents()).unwrap();
        let raw = payload_of(&text).replacen("\"wall\":3", "\"wall\":9", 1);
        match decode(&with_payload(&raw)) {
            Err(StoreError::Inconsistent(why)) => assert!(why.contains("wall 9"), "{why}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_map_that_would_not_load_is_not_saved() {
        let mut c = contents();
        c.walls[0].line.xc = f64::NAN;
        assert!(encode(&c).is_err());
        let mut c = contents();
        c.walls[0].id = crate::geometry::SegmentId(4_000_000_000);
        let text = encode(&c).unwrap();
        assert!(matches!(decode(&text), Err(StoreError::Inconsistent(_))));
    }

    #[test]
    fn an_edited_map_loads_only_when_its_checksum_is_ignored() {
        let text = encode(&contents()).unwrap();
        // An edit by hand: one number changed, the checksum left as it was.
        let edited = text.replacen("0.005", "0.010", 1);
        assert_ne!(edited, text);
        assert!(matches!(decode(&edited), Err(StoreError::Checksum { .. })));
        let loaded = decode_with(&edited, ChecksumCheck::Ignore).unwrap();
        let m = loaded.checksum_mismatch.unwrap();
        assert_ne!(m.stored, m.computed);
        let original = decode(&text).unwrap();
        assert!(original.checksum_mismatch.is_none());
        assert_ne!(
            format!("{:?}", loaded.contents),
            format!("{:?}", original.contents),
            "the edit is in the map loaded"
        );
        // An intact file under Ignore reports nothing.
        let intact = decode_with(&text, ChecksumCheck::Ignore).unwrap();
        assert!(intact.checksum_mismatch.is_none());
        // Ignoring the checksum skips no other check.
        let broken = edited.replacen("\"to\":1", "\"to\":9", 1);
        assert!(matches!(
            decode_with(&broken, ChecksumCheck::Ignore),
            Err(StoreError::Inconsistent(_))
        ));
        // Version 1 likewise: a corner moved on both its segments loads;
        // one moved on one segment opens the loop, refused all the same.
        let v1 = store::encode(&items(square().shapes())).unwrap();
        let v1_edited = v1.replace("[3.0,2.0]", "[3.5,2.0]");
        assert!(matches!(
            decode(&v1_edited),
            Err(StoreError::Checksum { .. })
        ));
        let back = decode_with(&v1_edited, ChecksumCheck::Ignore).unwrap();
        assert_eq!(back.version, 1);
        assert!(back.checksum_mismatch.is_some());
        let v1_open = v1.replacen("[3.0,2.0]", "[3.5,2.0]", 1);
        assert!(matches!(
            decode_with(&v1_open, ChecksumCheck::Ignore),
            Err(StoreError::Invariant(_))
        ));
    }

    #[test]
    fn version_1_files_still_load_with_the_cls_map_alone() {
        let v1 = store::encode(&items(square().shapes())).unwrap();
        let back = decode(&v1).unwrap();
        assert_eq!(back.version, 1);
        assert_eq!(back.contents.cls.items(), square().items());
        assert!(back.contents.walls.is_empty() && back.contents.keyframes.is_empty());
    }

    /// A file with `payload` and a checksum that matches it: a
    /// consistent-looking file with whatever content.
    fn with_payload(payload: &str) -> String {
        let header = String::from_utf8(header_bytes().unwrap()).unwrap();
        format!(
            "{header}{payload},\n\"checksum\":{}}}\n",
            crc32(payload.as_bytes())
        )
    }

    /// The payload of `text` as stored.
    fn payload_of(text: &str) -> &str {
        let start = text.find("\"payload\":").unwrap() + "\"payload\":".len();
        let end = text.rfind(",\n\"checksum\":").unwrap();
        &text[start..end]
    }

    #[test]
    fn corrupt_forged_and_inconsistent_files_are_refused_with_the_reason() {
        let text = encode(&contents()).unwrap();
        let flipped = text.replacen("0.005", "0.006", 1);
        assert!(matches!(decode(&flipped), Err(StoreError::Checksum { .. })));
        assert!(matches!(
            decode(&text[..text.len() - 20]),
            Err(StoreError::Truncated(_))
        ));
        // Zero checksum, escaped key, edited numbers: still a mismatch.
        let at = text.find("\"checksum\":").unwrap() + "\"checksum\":".len();
        let end = at + text[at..].find('}').unwrap();
        let forged = format!("{}0{}", &text[..at], &text[end..])
            .replace("\"payload\"", "\"p\\u0061yload\"")
            .replacen("0.005", "0.5", 1);
        assert!(matches!(
            decode(&forged),
            Err(StoreError::Checksum { stored: 0, .. })
        ));
        let v4 = text.replacen("\"version\":3", "\"version\":4", 1);
        assert!(matches!(decode(&v4), Err(StoreError::Version { found: 4 })));
        let foreign = text.replacen("clsmap-map", "someone-else", 1);
        assert!(matches!(decode(&foreign), Err(StoreError::Format(_))));

        let raw = payload_of(&text);
        assert_eq!(decode(&with_payload(raw)).unwrap().version, 3);
        let bad_edge = with_payload(&raw.replacen("\"to\":1", "\"to\":9", 1));
        match decode(&bad_edge) {
            Err(StoreError::Inconsistent(why)) => assert!(why.contains("edge 0"), "{why}"),
            other => panic!("{other:?}"),
        }
        let bad_source = with_payload(&raw.replacen("\"lines\":[0,", "\"lines\":[5,", 1));
        match decode(&bad_source) {
            Err(StoreError::Inconsistent(why)) => assert!(why.contains("keyframe 0"), "{why}"),
            other => panic!("{other:?}"),
        }
        let twice = with_payload(&raw.replacen("\"id\":3", "\"id\":3},{\"id\":3,\"observations\":1,\"line\":{\"theta\":0.0,\"xc\":0.0,\"yc\":0.0,\"sigma_theta\":0.1,\"sigma_c\":0.1,\"start\":[0.0,0.0],\"end\":[1.0,0.0],\"n_points\":5}", 1));
        assert!(decode(&twice).is_err());
        let negative = with_payload(&raw.replacen(
            "\"information\":[[10000.0",
            "\"information\":[[-10000.0",
            1,
        ));
        match decode(&negative) {
            Err(StoreError::Inconsistent(why)) => assert!(why.contains("semi-definite"), "{why}"),
            other => panic!("{other:?}"),
        }
        assert!(decode(&with_payload(&raw.replacen("\"t\":1.0", "\"t\":1e999", 1))).is_err());
    }
}
