//! rosbag2 bags in MCAP: the `ros2` profile, one channel per topic with
//! the type's `ros2msg` schema and CDR messages, stamped in nanoseconds.
//!
//! [`BagWriter`] writes a bag that `ros2 bag`, Foxglove and PyPI `rosbags`
//! read (chunked, zstd-compressed, with the summary and indexes).
//! [`BagReader`] streams any rosbag2 MCAP bag, a `.mcap` file or a bag
//! directory with one or more `.mcap` files, in file order, with bounded
//! memory. A bag that ends early (the recorder lost power) gives every
//! message before the damage, then an error saying where it ends.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Record};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use thiserror::Error;

use super::msg::RosMessage;

/// Longest record read (bytes): far above a laser scan or a map message,
/// and a bound on what a corrupt length can make the reader allocate.
pub const MAX_RECORD_BYTES: usize = 256 << 20;
/// Longest summary section read (bytes).
const MAX_SUMMARY_BYTES: u64 = 64 << 20;
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// What went wrong with a bag.
#[derive(Debug, Error)]
pub enum BagError {
    #[error("cannot open {}", path.display())]
    Open {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "{} is a rosbag2 SQLite bag; only MCAP bags are read: convert it with \
         `ros2 bag convert` (storage_id: mcap)",
        path.display()
    )]
    Sqlite { path: PathBuf },
    #[error("{} holds no .mcap file", path.display())]
    NoBagFiles { path: PathBuf },
    #[error("{} is not an MCAP file (its first bytes are not the MCAP magic)", path.display())]
    NotMcap { path: PathBuf },
    #[error("{}: profile `{profile}` is not a ROS 2 bag's (`ros2`)", path.display())]
    NotRos2 { path: PathBuf, profile: String },
    #[error(
        "{} ends early near byte {at}, without the MCAP footer: every message before \
         was read",
        path.display()
    )]
    EndsEarly { path: PathBuf, at: u64 },
    #[error("{} is damaged near byte {at}", path.display())]
    Damaged {
        path: PathBuf,
        at: u64,
        #[source]
        source: mcap::McapError,
    },
    #[error("reading {} failed", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "cannot create the bag {} (an existing file is never overwritten)",
        path.display()
    )]
    Create {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("writing the bag {} failed", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: mcap::McapError,
    },
}

/// One topic of a bag: its name, message type and encoding.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    pub topic: String,
    /// `pkg/msg/Type`, from the channel's schema (empty without one).
    pub type_name: String,
    /// `cdr` for ROS 2 bags.
    pub encoding: String,
}

/// One message as stored: its topic, receive time and serialized bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct BagMessage {
    pub topic: TopicInfo,
    /// When the recorder received it (ns since the epoch).
    pub log_time: u64,
    pub data: Vec<u8>,
}

/// QoS durability a topic was offered with: `TransientLocal` for latched
/// topics (`/tf_static`, `/map`), so a bag player offers them so again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    Volatile,
    TransientLocal,
}

impl Durability {
    /// rosbag2's `offered_qos_profiles` entry (YAML, numeric enums:
    /// history keep-last, depth, reliability reliable, durability 1
    /// transient-local or 2 volatile, liveliness automatic, and the
    /// "infinite" durations).
    fn offered_qos(self) -> String {
        let durability = match self {
            Durability::TransientLocal => 1,
            Durability::Volatile => 2,
        };
        let infinite = "\n    sec: 2147483647\n    nsec: 4294967295";
        format!(
            "- history: 1\n  depth: 10\n  reliability: 1\n  durability: {durability}\n  \
             deadline:{infinite}\n  lifespan:{infinite}\n  liveliness: 1\n  \
             liveliness_lease_duration:{infinite}\n  avoid_ros_namespace_conventions: false\n"
        )
    }
}

/// A topic added to a [`BagWriter`], of any type ([`BagTopic`] is the
/// typed form).
#[derive(Debug)]
pub struct RawTopic {
    channel: u16,
    sequence: u32,
}

/// A topic added to a [`BagWriter`], typed by its message.
#[derive(Debug)]
pub struct BagTopic<M> {
    raw: RawTopic,
    _message: PhantomData<M>,
}

/// Writes a rosbag2 MCAP bag.
pub struct BagWriter {
    mcap: mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    schemas: HashMap<String, u16>,
}

impl std::fmt::Debug for BagWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagWriter")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl BagWriter {
    /// Creates `path`; an existing file is never overwritten (it may be
    /// the only copy of a run).
    pub fn create(path: &Path) -> Result<BagWriter, BagError> {
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|source| BagError::Create {
                path: path.to_owned(),
                source,
            })?;
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("clsmap ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|source| BagError::Write {
                path: path.to_owned(),
                source,
            })?;
        Ok(BagWriter {
            mcap,
            path: path.to_owned(),
            schemas: HashMap::new(),
        })
    }

    fn write_error(&self, source: mcap::McapError) -> BagError {
        BagError::Write {
            path: self.path.clone(),
            source,
        }
    }

    /// Adds a topic of message type `M`.
    pub fn topic<M: RosMessage>(
        &mut self,
        name: &str,
        durability: Durability,
    ) -> Result<BagTopic<M>, BagError> {
        Ok(BagTopic {
            raw: self.raw_topic(name, M::TYPE, &M::definition(), durability)?,
            _message: PhantomData,
        })
    }

    /// Adds a topic of type `type_name` (`pkg/msg/Type`) whose schema is
    /// `definition` (`ros2msg`).
    pub fn raw_topic(
        &mut self,
        name: &str,
        type_name: &str,
        definition: &str,
        durability: Durability,
    ) -> Result<RawTopic, BagError> {
        let schema = match self.schemas.get(type_name) {
            Some(&id) => id,
            None => {
                let id = self
                    .mcap
                    .add_schema(type_name, "ros2msg", definition.as_bytes())
                    .map_err(|e| self.write_error(e))?;
                self.schemas.insert(type_name.to_string(), id);
                id
            }
        };
        let metadata =
            BTreeMap::from([("offered_qos_profiles".to_string(), durability.offered_qos())]);
        let channel = self
            .mcap
            .add_channel(schema, name, "cdr", &metadata)
            .map_err(|e| self.write_error(e))?;
        Ok(RawTopic {
            channel,
            sequence: 0,
        })
    }

    /// Writes `message` on `topic`, received at `log_time` (ns since the
    /// epoch).
    pub fn write<M: RosMessage>(
        &mut self,
        topic: &mut BagTopic<M>,
        log_time: u64,
        message: &M,
    ) -> Result<(), BagError> {
        self.write_raw(&mut topic.raw, log_time, &message.to_cdr())
    }

    /// Writes a serialized message (CDR, header included) on `topic`.
    pub fn write_raw(
        &mut self,
        topic: &mut RawTopic,
        log_time: u64,
        cdr: &[u8],
    ) -> Result<(), BagError> {
        topic.sequence = topic.sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id: topic.channel,
            sequence: topic.sequence,
            log_time,
            publish_time: log_time,
        };
        self.mcap
            .write_to_known_channel(&header, cdr)
            .map_err(|e| self.write_error(e))
    }

    /// Closes the chunk in progress and hands it to the file, so a crash
    /// loses at most what came after.
    pub fn flush(&mut self) -> Result<(), BagError> {
        self.mcap.flush().map_err(|e| self.write_error(e))
    }

    /// Writes the summary and the footer and syncs the file to disk.
    pub fn finish(mut self) -> Result<(), BagError> {
        self.mcap.finish().map_err(|e| self.write_error(e))?;
        let path = self.path.clone();
        let file = self
            .mcap
            .into_inner()
            .into_inner()
            .map_err(|e| BagError::Write {
                path: path.clone(),
                source: e.into_error().into(),
            })?;
        file.sync_all().map_err(|e| BagError::Write {
            path,
            source: e.into(),
        })
    }
}

/// The `.mcap` files of a bag at `path`, in recording order: the file
/// itself, or a rosbag2 directory's files by their split number
/// (`name_0.mcap`, `name_1.mcap`, … `name_10.mcap`).
pub fn bag_files(path: &Path) -> Result<Vec<PathBuf>, BagError> {
    let open_error = |source| BagError::Open {
        path: path.to_owned(),
        source,
    };
    let meta = std::fs::metadata(path).map_err(open_error)?;
    if !meta.is_dir() {
        if path.extension().is_some_and(|e| e == "db3") {
            return Err(BagError::Sqlite {
                path: path.to_owned(),
            });
        }
        return Ok(vec![path.to_owned()]);
    }
    let mut files = Vec::new();
    let mut sqlite = false;
    for entry in std::fs::read_dir(path).map_err(open_error)? {
        let p = entry.map_err(open_error)?.path();
        match p.extension().and_then(|e| e.to_str()) {
            Some("mcap") => files.push(p),
            Some("db3") => sqlite = true,
            _ => {}
        }
    }
    if files.is_empty() {
        return Err(if sqlite {
            BagError::Sqlite {
                path: path.to_owned(),
            }
        } else {
            BagError::NoBagFiles {
                path: path.to_owned(),
            }
        });
    }
    let split = |p: &PathBuf| {
        p.file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| s.rsplit('_').next())
            .and_then(|n| n.parse::<u64>().ok())
    };
    files.sort_by(|a, b| split(a).cmp(&split(b)).then_with(|| a.cmp(b)));
    Ok(files)
}

/// Streams the messages of a bag (all its files, in order).
pub struct BagReader {
    files: std::vec::IntoIter<PathBuf>,
    current: Option<FileReader>,
    failed: bool,
    /// Bytes of the files already read through.
    done_bytes: u64,
    /// The topics every file's summary lists, when each has one.
    summary: Option<Vec<TopicInfo>>,
}

impl std::fmt::Debug for BagReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagReader")
            .field("path", &self.current.as_ref().map(|c| &c.path))
            .finish_non_exhaustive()
    }
}

impl BagReader {
    /// Opens a `.mcap` file or a rosbag2 bag directory.
    pub fn open(path: &Path) -> Result<BagReader, BagError> {
        let paths = bag_files(path)?;
        let mut files = paths.clone().into_iter();
        let first = files.next().map(|p| FileReader::open(&p)).transpose()?;
        // The later splits' summaries too: a topic may start in any.
        let mut summary = first.as_ref().and_then(|f| f.summary.clone());
        for p in paths.iter().skip(1) {
            let Some(topics) = summary.as_mut() else {
                break;
            };
            let read_error = |source| BagError::Read {
                path: p.to_owned(),
                source,
            };
            let mut file = File::open(p).map_err(read_error)?;
            match read_summary(&mut file).map_err(read_error)? {
                Some(more) => {
                    for t in more {
                        if !topics
                            .iter()
                            .any(|k| k.topic == t.topic && k.type_name == t.type_name)
                        {
                            topics.push(t);
                        }
                    }
                }
                None => summary = None,
            }
        }
        Ok(BagReader {
            files,
            current: first,
            failed: false,
            done_bytes: 0,
            summary,
        })
    }

    /// Bytes read so far, over all the bag's files.
    pub fn bytes_read(&self) -> u64 {
        self.done_bytes + self.current.as_ref().map_or(0, |c| c.offset)
    }

    /// The topics the summaries of the bag's files list, if each file
    /// has one (a file cut short has none; the topics are then known as
    /// they come).
    pub fn summary_topics(&self) -> Option<&[TopicInfo]> {
        self.summary.as_deref()
    }
}

impl Iterator for BagReader {
    type Item = Result<BagMessage, BagError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        loop {
            let current = self.current.as_mut()?;
            match current.next_message() {
                Some(Ok(m)) => return Some(Ok(m)),
                Some(Err(e)) => {
                    self.failed = true;
                    return Some(Err(e));
                }
                None => {
                    self.done_bytes += current.offset;
                    let next = self.files.next().map(|p| FileReader::open(&p));
                    match next {
                        Some(Ok(next)) => self.current = Some(next),
                        Some(Err(e)) => {
                            self.failed = true;
                            return Some(Err(e));
                        }
                        None => {
                            self.current = None;
                            return None;
                        }
                    }
                }
            }
        }
    }
}

/// One `.mcap` file being streamed.
struct FileReader {
    path: PathBuf,
    file: File,
    reader: LinearReader,
    /// Bytes handed to the reader so far.
    offset: u64,
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, TopicInfo>,
    summary: Option<Vec<TopicInfo>>,
    header_checked: bool,
}

impl FileReader {
    fn open(path: &Path) -> Result<FileReader, BagError> {
        let mut file = File::open(path).map_err(|source| BagError::Open {
            path: path.to_owned(),
            source,
        })?;
        let read_error = |source| BagError::Read {
            path: path.to_owned(),
            source,
        };
        let mut magic = [0u8; 8];
        if file.read_exact(&mut magic).is_err() || &magic != MAGIC {
            return Err(BagError::NotMcap {
                path: path.to_owned(),
            });
        }
        let summary = read_summary(&mut file).map_err(read_error)?;
        file.seek(SeekFrom::Start(0)).map_err(read_error)?;
        let options = LinearReaderOptions::default().with_record_length_limit(MAX_RECORD_BYTES);
        Ok(FileReader {
            path: path.to_owned(),
            file,
            reader: LinearReader::new_with_options(options),
            offset: 0,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            summary,
            header_checked: false,
        })
    }

    fn next_message(&mut self) -> Option<Result<BagMessage, BagError>> {
        loop {
            let event = match self.reader.next_event()? {
                Ok(event) => event,
                Err(mcap::McapError::UnexpectedEof) => {
                    return Some(Err(BagError::EndsEarly {
                        path: self.path.clone(),
                        at: self.offset,
                    }));
                }
                Err(source) => {
                    return Some(Err(BagError::Damaged {
                        path: self.path.clone(),
                        at: self.offset,
                        source,
                    }));
                }
            };
            let (opcode, data) = match event {
                LinearReadEvent::ReadRequest(need) => {
                    let buf = self.reader.insert(need);
                    match self.file.read(buf) {
                        Ok(n) => {
                            self.reader.notify_read(n);
                            self.offset += n as u64;
                        }
                        Err(source) => {
                            return Some(Err(BagError::Read {
                                path: self.path.clone(),
                                source,
                            }));
                        }
                    }
                    continue;
                }
                LinearReadEvent::Record { opcode, data } => (opcode, data),
            };
            let record = match mcap::parse_record(opcode, data) {
                Ok(r) => r,
                Err(source) => {
                    return Some(Err(BagError::Damaged {
                        path: self.path.clone(),
                        at: self.offset,
                        source,
                    }));
                }
            };
            match record {
                Record::Header(h) if !self.header_checked => {
                    self.header_checked = true;
                    if h.profile != "ros2" {
                        return Some(Err(BagError::NotRos2 {
                            path: self.path.clone(),
                            profile: h.profile,
                        }));
                    }
                }
                Record::Schema { header, .. } => {
                    self.schemas.insert(header.id, header.name);
                }
                Record::Channel(c) => {
                    let type_name = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                    self.channels.insert(
                        c.id,
                        TopicInfo {
                            topic: c.topic,
                            type_name,
                            encoding: c.message_encoding,
                        },
                    );
                }
                Record::Message { header, data } => {
                    // A message of an unknown channel cannot be decoded:
                    // no ROS 2 writer emits one, so it is passed over.
                    if let Some(topic) = self.channels.get(&header.channel_id) {
                        return Some(Ok(BagMessage {
                            topic: topic.clone(),
                            log_time: header.log_time,
                            data: data.into_owned(),
                        }));
                    }
                }
                _ => {}
            }
        }
    }
}

/// The topics of the summary section, found through the footer; `None`
/// when the file has no summary or no intact footer.
fn read_summary(file: &mut File) -> std::io::Result<Option<Vec<TopicInfo>>> {
    let len = file.seek(SeekFrom::End(0))?;
    // Footer record (1 + 8 + 20 bytes) and the closing magic.
    if len < 8 + 37 {
        return Ok(None);
    }
    file.seek(SeekFrom::Start(len - 37))?;
    let mut tail = [0u8; 37];
    file.read_exact(&mut tail)?;
    if &tail[29..] != MAGIC || tail[0] != 0x02 {
        return Ok(None);
    }
    let u64_at = |i: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&tail[i..i + 8]);
        u64::from_le_bytes(b)
    };
    let summary_start = u64_at(9);
    let footer_start = len - 37;
    if summary_start == 0
        || summary_start < 8
        || summary_start > footer_start
        || footer_start - summary_start > MAX_SUMMARY_BYTES
    {
        return Ok(None);
    }
    file.seek(SeekFrom::Start(summary_start))?;
    let mut bytes = vec![0u8; (footer_start - summary_start) as usize];
    file.read_exact(&mut bytes)?;
    let mut schemas = HashMap::new();
    let mut topics = Vec::new();
    let mut at = 0usize;
    while at + 9 <= bytes.len() {
        let op = bytes[at];
        let mut l = [0u8; 8];
        l.copy_from_slice(&bytes[at + 1..at + 9]);
        let Some(end) = usize::try_from(u64::from_le_bytes(l))
            .ok()
            .and_then(|n| (at + 9).checked_add(n))
            .filter(|&e| e <= bytes.len())
        else {
            return Ok(None);
        };
        match mcap::parse_record(op, &bytes[at + 9..end]) {
            Ok(Record::Schema { header, .. }) => {
                schemas.insert(header.id, header.name);
            }
            Ok(Record::Channel(c)) => topics.push((c.schema_id, c.topic, c.message_encoding)),
            Ok(_) => {}
            Err(_) => return Ok(None),
        }
        at = end;
    }
    Ok(Some(
        topics
            .into_iter()
            .map(|(schema, topic, encoding)| TopicInfo {
                topic,
                type_name: schemas.get(&schema).cloned().unwrap_or_default(),
                encoding,
            })
            .collect(),
    ))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::ros2::msg::{ByteArray, DiagnosticArray, Header, LaserScan, Odometry, Time};

    fn scan(i: u32) -> LaserScan {
        LaserScan {
            header: Header {
                stamp: Time {
                    sec: 10,
                    nanosec: i,
                },
                frame_id: "laser".into(),
            },
            angle_increment: 0.01,
            ranges: vec![i as f32; 361],
            ..LaserScan::default()
        }
    }

    fn write_bag(path: &Path, scans: u32) {
        let mut bag = BagWriter::create(path).unwrap();
        let mut s = bag
            .topic::<LaserScan>("/scan", Durability::Volatile)
            .unwrap();
        let mut o = bag
            .topic::<Odometry>("/odom", Durability::Volatile)
            .unwrap();
        let mut r = bag
            .topic::<ByteArray>("/raw", Durability::Volatile)
            .unwrap();
        for i in 0..scans {
            bag.write(&mut s, 10_000_000_000 + u64::from(i), &scan(i))
                .unwrap();
            bag.write(&mut o, 10_000_000_000 + u64::from(i), &Odometry::default())
                .unwrap();
            bag.write(
                &mut r,
                10_000_000_000 + u64::from(i),
                &ByteArray {
                    data: vec![2, 0x80],
                },
            )
            .unwrap();
            if i % 100 == 99 {
                bag.flush().unwrap();
            }
        }
        bag.finish().unwrap();
    }

    #[test]
    fn a_bag_reads_back_in_order_with_its_topics() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.mcap");
        write_bag(&path, 250);
        let reader = BagReader::open(&path).unwrap();
        let topics = reader.summary_topics().unwrap().to_vec();
        assert_eq!(topics.len(), 3);
        assert!(topics.iter().any(|t| t.topic == "/scan"
            && t.type_name == "sensor_msgs/msg/LaserScan"
            && t.encoding == "cdr"));
        let messages: Vec<BagMessage> = reader.map(Result::unwrap).collect();
        assert_eq!(messages.len(), 750);
        let scans: Vec<LaserScan> = messages
            .iter()
            .filter(|m| m.topic.topic == "/scan")
            .map(|m| LaserScan::from_cdr(&m.data).unwrap())
            .collect();
        assert_eq!(scans, (0..250).map(scan).collect::<Vec<_>>());
        // An existing file is never overwritten.
        assert!(matches!(
            BagWriter::create(&path).unwrap_err(),
            BagError::Create { .. }
        ));
    }

    #[test]
    fn a_bag_cut_short_gives_what_it_holds_then_says_where_it_ends() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.mcap");
        write_bag(&path, 250);
        let bytes = std::fs::read(&path).unwrap();
        let cut = dir.path().join("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
        let reader = BagReader::open(&cut).unwrap();
        assert!(reader.summary_topics().is_none());
        let items: Vec<_> = reader.collect();
        let (ok, err): (Vec<_>, Vec<_>) = items.into_iter().partition(Result::is_ok);
        // The chunks flushed before the cut are whole.
        assert!(ok.len() >= 300, "{}", ok.len());
        assert_eq!(err.len(), 1);
        assert!(matches!(err[0], Err(BagError::EndsEarly { .. })), "{err:?}");
    }

    #[test]
    fn foreign_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let text = dir.path().join("log.mcap");
        std::fs::write(&text, "FLASER 0\n").unwrap();
        assert!(matches!(
            BagReader::open(&text).unwrap_err(),
            BagError::NotMcap { .. }
        ));
        let bag = dir.path().join("bag");
        std::fs::create_dir(&bag).unwrap();
        assert!(matches!(
            BagReader::open(&bag).unwrap_err(),
            BagError::NoBagFiles { .. }
        ));
        std::fs::write(bag.join("bag_0.db3"), "").unwrap();
        assert!(matches!(
            BagReader::open(&bag).unwrap_err(),
            BagError::Sqlite { .. }
        ));
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// A damaged bag (flipped bytes, a cut) gives messages and errors,
        /// never a panic; the messages before the damage are intact.
        #[test]
        fn a_damaged_bag_never_panics(
            flips in proptest::collection::vec((0usize..20_000, 1u8..=255), 0..6),
            cut in 0usize..20_000,
        ) {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("run.mcap");
            write_bag(&path, 40);
            let mut bytes = std::fs::read(&path).unwrap();
            let len = bytes.len();
            for (at, x) in flips {
                bytes[at % len] ^= x;
            }
            bytes.truncate(cut.max(8).min(bytes.len()));
            let damaged = dir.path().join("damaged.mcap");
            std::fs::write(&damaged, &bytes).unwrap();
            if let Ok(reader) = BagReader::open(&damaged) {
                for m in reader.take(1000).flatten() {
                    if m.topic.topic == "/scan" {
                        let _ = LaserScan::from_cdr(&m.data);
                    }
                }
            }
        }
    }

    #[test]
    fn a_directory_s_files_are_read_in_split_order() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["b_10.mcap", "b_2.mcap", "b_0.mcap"] {
            std::fs::write(dir.path().join(name), "").unwrap();
        }
        let names: Vec<_> = bag_files(dir.path())
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_str().unwrap().to_string())
            .collect();
        assert_eq!(names, ["b_0.mcap", "b_2.mcap", "b_10.mcap"]);
    }

    #[test]
    fn a_split_bag_lists_the_topics_of_every_split() {
        let dir = tempfile::tempdir().unwrap();
        write_bag(&dir.path().join("b_0.mcap"), 10);
        let mut later = BagWriter::create(&dir.path().join("b_1.mcap")).unwrap();
        let mut d = later
            .topic::<DiagnosticArray>("/diagnostics", Durability::Volatile)
            .unwrap();
        later
            .write(&mut d, 20_000_000_000, &DiagnosticArray::default())
            .unwrap();
        later.finish().unwrap();
        let reader = BagReader::open(dir.path()).unwrap();
        let topics: Vec<&str> = reader
            .summary_topics()
            .unwrap()
            .iter()
            .map(|t| t.topic.as_str())
            .collect();
        assert_eq!(topics.len(), 4, "{topics:?}");
        assert!(topics.contains(&"/diagnostics") && topics.contains(&"/scan"));
        assert_eq!(reader.count(), 31);
        // A split cut short has no summary: the topics are not known ahead.
        let bytes = std::fs::read(dir.path().join("b_1.mcap")).unwrap();
        std::fs::write(dir.path().join("b_1.mcap"), &bytes[..bytes.len() - 40]).unwrap();
        assert!(
            BagReader::open(dir.path())
                .unwrap()
                .summary_topics()
                .is_none()
        );
    }
}
