//! The shell that writes the core's ROS 2 messages into a rosbag2 bag, on
//! a thread of its own: compressing a chunk takes milliseconds the loop
//! does not have. The loop hands messages over without waiting; if the
//! disk falls behind, messages are dropped and counted, never the loop
//! held up.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tracing::{error, info};

use super::handoff::Handoff;
use super::ros2_out::{Stamped, TOPICS};
use crate::ros2::bag::{BagError, BagWriter, Durability, RawTopic};

/// The bag's name in the run's directory.
pub const BAG_FILE: &str = "run.mcap";

/// Messages in flight to the writer at most (about 5 s of scans).
const QUEUE: usize = 1024;
/// A chunk is closed (and so safe from a crash) at least this often.
const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// A bag being written.
#[derive(Debug)]
pub struct BagSink {
    queue: Handoff<Stamped>,
    thread: Option<JoinHandle<Result<u64, BagError>>>,
    path: PathBuf,
}

impl BagSink {
    /// Creates `path` (never over an existing file) and starts the writer.
    pub fn start(path: &Path) -> Result<BagSink, BagError> {
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
        let (queue, rx) = Handoff::new(QUEUE, "the bag writer");
        let thread = std::thread::Builder::new()
            .name("clsmap-bag".into())
            .spawn(move || write_all(bag, topics, &rx))
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

fn write_all(
    mut bag: BagWriter,
    mut topics: Vec<RawTopic>,
    rx: &Receiver<Stamped>,
) -> Result<u64, BagError> {
    let mut written = 0u64;
    let mut last_flush = Instant::now();
    loop {
        match rx.recv_timeout(FLUSH_EVERY) {
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
        if last_flush.elapsed() >= FLUSH_EVERY {
            bag.flush()?;
            last_flush = Instant::now();
        }
    }
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
        let mut sink = BagSink::start(&path).unwrap();
        let mut out = Ros2Outbox::new(1_700_000_000.0, Pose2::IDENTITY, 8.183);
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
        assert!(BagSink::start(&path).is_err());
    }
}
