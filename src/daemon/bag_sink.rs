//! The shell that writes the core's ROS 2 messages into a rosbag2 bag, on
//! a thread of its own: compressing a chunk takes milliseconds the loop
//! does not have. The loop hands messages over without waiting; if the
//! disk falls behind, messages are dropped and counted, never the loop
//! held up. The raw serial stream, when given, goes on its own topic
//! ([`RECORDING_TOPIC`]), so nothing the sensor sent is lost.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tracing::{error, info};

use super::handoff::Handoff;
use super::ros2_out::{RECORDING_TOPIC, Stamped, TOPICS};
use super::sensor::RawTelegrams;
use crate::ros2::bag::{BagError, BagTopic, BagWriter, Durability, RawTopic};
use crate::ros2::{ByteArray, Time};

/// The bag's name in the run's directory.
pub const BAG_FILE: &str = "run.mcap";

/// Messages in flight to the writer at most (about 5 s of scans).
const QUEUE: usize = 1024;
/// A chunk is closed (and so safe from a crash) at least this often.
const FLUSH_EVERY: Duration = Duration::from_secs(1);
/// The raw stream is moved into a message at least this often.
const RAW_EVERY: Duration = Duration::from_millis(200);

/// A bag being written.
#[derive(Debug)]
pub struct BagSink {
    queue: Handoff<Stamped>,
    thread: Option<JoinHandle<Result<u64, BagError>>>,
    path: PathBuf,
}

impl BagSink {
    /// Creates `path` (never over an existing file) and starts the writer;
    /// with `raw`, the serial stream goes into the bag too.
    pub fn start(path: &Path, raw: Option<RawTelegrams>) -> Result<BagSink, BagError> {
        let mut bag = BagWriter::create(path)?;
        let topics = TOPICS
            .iter()
            .map(|t| {
                let durability = match t.latched {
                    true => Durability::TransientLocal,
                    false => Durability::Volatile,
                };
                let name = format!("/{}", t.name);
                bag.raw_topic(&name, t.type_name, &(t.definition)(), durability)
            })
            .collect::<Result<Vec<RawTopic>, BagError>>()?;
        let raw = match raw {
            Some(bytes) => Some((
                bag.topic::<ByteArray>(RECORDING_TOPIC, Durability::Volatile)?,
                bytes,
            )),
            None => None,
        };
        let (queue, rx) = Handoff::new(QUEUE, "the bag writer");
        let thread = std::thread::Builder::new()
            .name("clsmap-bag".into())
            .spawn(move || write_all(bag, topics, raw, &rx))
            .map_err(|source| BagError::Create {
                path: path.to_owned(),
                source,
            })?;
        info!(path = %path.display(), "writing a rosbag2 bag of the run");
        Ok(BagSink {
            queue,
            thread: Some(thread),
            path: path.to_owned(),
        })
    }

    /// Hands `messages` to the writer without waiting.
    pub fn send(&mut self, messages: Vec<Stamped>) {
        for m in messages {
            self.queue.send(m);
        }
    }

    /// Writes what is queued, the summary and the footer; returns the
    /// bag's path and how many messages it holds.
    pub fn finish(mut self) -> Result<(PathBuf, u64), BagError> {
        self.queue.close();
        let written = match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result?,
            Some(Err(_)) | None => 0,
        };
        Ok((self.path.clone(), written))
    }
}

/// Moves the raw stream's new bytes into a message stamped now.
fn write_raw(
    bag: &mut BagWriter,
    raw: &mut Option<(BagTopic<ByteArray>, RawTelegrams)>,
    written: &mut u64,
) -> Result<(), BagError> {
    let Some((topic, bytes)) = raw.as_mut() else {
        return Ok(());
    };
    let (data, dropped) = bytes.take();
    if dropped > 0 {
        error!(
            bytes = dropped,
            "raw telegrams did not reach the bag (its writer fell behind)"
        );
    }
    if data.is_empty() {
        return Ok(());
    }
    let now = lms200::driver::unix_micros() as f64 / 1e6;
    let ns = Time::from_secs(now).unwrap_or_default().as_nanos();
    bag.write(topic, ns, &ByteArray { data })?;
    *written += 1;
    Ok(())
}

fn write_all(
    mut bag: BagWriter,
    mut topics: Vec<RawTopic>,
    mut raw: Option<(BagTopic<ByteArray>, RawTelegrams)>,
    rx: &Receiver<Stamped>,
) -> Result<u64, BagError> {
    let mut written = 0u64;
    let mut last_flush = Instant::now();
    let mut last_raw = Instant::now();
    loop {
        let wait = if raw.is_some() {
            RAW_EVERY
        } else {
            FLUSH_EVERY
        };
        match rx.recv_timeout(wait) {
            Ok(Stamped { stamp_ns, message }) => {
                let result = match (message.encode(), topics.get_mut(message.topic_index())) {
                    (Some(cdr), Some(topic)) => bag.write_raw(topic, stamp_ns, &cdr),
                    _ => Ok(()),
                };
                if let Err(e) = result {
                    error!("the bag stops here: {}", crate::error_chain(&e));
                    return Err(e);
                }
                written += 1;
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if last_raw.elapsed() >= RAW_EVERY {
            write_raw(&mut bag, &mut raw, &mut written)?;
            last_raw = Instant::now();
        }
        if last_flush.elapsed() >= FLUSH_EVERY {
            bag.flush()?;
            last_flush = Instant::now();
        }
    }
    write_raw(&mut bag, &mut raw, &mut written)?;
    bag.finish()?;
    Ok(written)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::daemon::ros2_out::Ros2Outbox;
    use crate::geometry::{Pose2, RangeScan};
    use crate::ros2::bag::BagReader;

    #[test]
    fn the_outbox_s_messages_land_in_the_bag_on_their_topics() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.mcap");
        let mut sink = BagSink::start(&path, None).unwrap();
        let mut out = Ros2Outbox::new(
            1_700_000_000.0,
            Pose2::IDENTITY,
            8.183,
            &crate::daemon::config::Ros2Section::default(),
            false,
        );
        for k in 0..30 {
            let scan = RangeScan {
                t: f64::from(k) * 0.1,
                angle_min: -1.0,
                angle_increment: 0.01,
                ranges: vec![Ok(1.0); 201],
            };
            out.scan(
                &scan,
                Pose2::new(0.1 * f64::from(k), 0.0, 0.0),
                &[[0.0; 3]; 3],
                Some(Pose2::IDENTITY),
            );
            sink.send(out.take());
        }
        let (p, written) = sink.finish().unwrap();
        assert_eq!(p, path);
        assert_eq!(written, 1 + 30 * 4);
        let topics: Vec<String> = BagReader::open(&path)
            .unwrap()
            .map(|m| m.unwrap().topic.topic)
            .collect();
        assert_eq!(topics.iter().filter(|t| *t == "/scan").count(), 30);
        assert_eq!(topics.iter().filter(|t| *t == "/tf_static").count(), 1);
        // An existing bag is never overwritten.
        assert!(BagSink::start(&path, None).is_err());
    }
}
