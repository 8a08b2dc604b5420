//! The shell that publishes the core's ROS 2 messages on DDS: a ROS 2 node
//! (ros2-client on RustDDS, pure Rust) on a thread of its own, which the
//! loop hands messages to without waiting (dropped and counted when DDS
//! falls behind).
//!
//! The messages go out as the bytes [`crate::ros2::msg`] serializes (the
//! ones checked against an independent serializer): every topic carries
//! them unchanged, so the DDS shell adds no second encoding. Every topic
//! is reliable (a reliable writer serves best-effort and reliable readers
//! alike: RViz, Foxglove and `ros2 topic echo` all match); `/tf_static`
//! and `/map` are transient-local, so a subscriber that joins late still
//! gets them.

use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::Duration;

use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher,
    QosProfile,
    qos::{Durability, History, WhenFull},
};
use serde::ser::{Serialize, SerializeTuple, Serializer};
use tracing::{info, warn};

use super::config::Ros2Section;
use super::ros2_out::{Ros2Message, Stamped, grid_message};
use crate::ros2::{
    LaserScan, OccupancyGrid, Odometry, PoseWithCovarianceStamped, RosMessage, TfMessage,
};

/// Messages in flight to the node at most (about 5 s of scans).
const QUEUE: usize = 1024;
/// Longest a reliable write waits for a slow reader before the message
/// is dropped.
const WRITE_WAIT: Duration = Duration::from_millis(20);

/// Why the node did not start.
#[derive(Debug, thiserror::Error)]
pub enum DdsError {
    #[error("cannot start the ROS 2 node: {0}")]
    Start(String),
}

/// A message's CDR body, written as it is: a tuple of bytes has neither a
/// length nor padding in CDR, and the body's alignment counts from its
/// first byte in both encoders.
struct CdrBody(Vec<u8>);

impl Serialize for CdrBody {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(self.0.len())?;
        for b in &self.0 {
            t.serialize_element(b)?;
        }
        t.end()
    }
}

fn body<M: RosMessage>(m: &M) -> CdrBody {
    let mut bytes = m.to_cdr();
    bytes.drain(..4);
    CdrBody(bytes)
}

/// The node's publishers.
struct Publishers {
    scan: Publisher<CdrBody>,
    pose: Publisher<CdrBody>,
    odom: Publisher<CdrBody>,
    tf: Publisher<CdrBody>,
    tf_static: Publisher<CdrBody>,
    map: Publisher<CdrBody>,
    /// Kept alive while publishing.
    _node: Node,
}

/// The ROS 2 node, publishing.
#[derive(Debug)]
pub struct DdsSink {
    tx: Option<SyncSender<Stamped>>,
    thread: Option<JoinHandle<()>>,
    dropped: u64,
}

/// `pkg/msg/Type` as ros2-client's type name.
fn type_name(full: &str) -> MessageTypeName {
    let mut parts = full.split('/');
    let package = parts.next().unwrap_or_default();
    let name = parts.next_back().unwrap_or_default();
    MessageTypeName::new(package, name)
}

fn start_node(cfg: &Ros2Section) -> Result<Publishers, String> {
    let context = Context::with_options(ContextOptions::new().domain_id(cfg.domain_id))
        .map_err(|e| format!("DDS participant: {e:?}"))?;
    let namespace = if cfg.namespace.is_empty() {
        "/"
    } else {
        cfg.namespace.as_str()
    };
    let mut node = context
        .new_node(
            NodeName::new(namespace, &cfg.node_name).map_err(|e| format!("node name: {e:?}"))?,
            NodeOptions::new()
                .enable_rosout(false)
                .start_parameter_services(false),
        )
        .map_err(|e| format!("node: {e:?}"))?;
    let reliable = QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(WRITE_WAIT))
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 });
    let latched = reliable
        .clone()
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 });
    let mut publisher = |topic: &str, ty: &str, qos: &QosProfile| {
        let name = Name::new(namespace, topic).map_err(|e| format!("topic {topic}: {e:?}"))?;
        let topic = node
            .create_topic(&name, type_name(ty), qos)
            .map_err(|e| format!("topic {topic}: {e:?}"))?;
        node.create_publisher::<CdrBody>(&topic, Some(qos.clone()))
            .map_err(|e| format!("publisher: {e:?}"))
    };
    let scan = publisher("scan", LaserScan::TYPE, &reliable)?;
    let pose = publisher("pose", PoseWithCovarianceStamped::TYPE, &reliable)?;
    let odom = publisher("odom", Odometry::TYPE, &reliable)?;
    let tf = publisher(
        "tf",
        TfMessage::TYPE,
        &reliable.clone().history(History::KeepLast { depth: 100 }),
    )?;
    let tf_static = publisher("tf_static", TfMessage::TYPE, &latched)?;
    let map = publisher("map", OccupancyGrid::TYPE, &latched)?;
    Ok(Publishers {
        map,
        scan,
        pose,
        odom,
        tf,
        tf_static,
        _node: node,
    })
}

impl DdsSink {
    /// Starts the node as `cfg` says; returns once its publishers exist.
    pub fn start(cfg: &Ros2Section) -> Result<DdsSink, DdsError> {
        let (tx, rx) = sync_channel::<Stamped>(QUEUE);
        let (ready_tx, ready_rx) = sync_channel::<Result<(), String>>(1);
        let cfg = cfg.clone();
        let thread = std::thread::Builder::new()
            .name("clsmap-ros2".into())
            .spawn(move || match start_node(&cfg) {
                Ok(p) => {
                    let _ = ready_tx.send(Ok(()));
                    publish_all(&p, &rx);
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                }
            })
            .map_err(|e| DdsError::Start(e.to_string()))?;
        match ready_rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(DdsError::Start(e)),
            Err(_) => return Err(DdsError::Start("the node's thread ended".into())),
        }
        info!("ROS 2 node up: publishing /scan /pose /odom /tf /tf_static /map");
        Ok(DdsSink {
            tx: Some(tx),
            thread: Some(thread),
            dropped: 0,
        })
    }

    /// Hands `messages` to the node without waiting.
    pub fn send(&mut self, messages: &[Stamped]) {
        let Some(tx) = &self.tx else { return };
        for m in messages {
            match tx.try_send(m.clone()) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => {
                    self.dropped += 1;
                    if self.dropped == 1 {
                        warn!("the ROS 2 node falls behind: messages are dropped");
                    }
                }
                Err(TrySendError::Disconnected(_)) => {
                    self.tx = None;
                    return;
                }
            }
        }
    }

    /// Stops the node.
    pub fn finish(mut self) {
        drop(self.tx.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if self.dropped > 0 {
            warn!(dropped = self.dropped, "messages were not published");
        }
    }
}

fn publish_all(p: &Publishers, rx: &Receiver<Stamped>) {
    let mut failures = 0u64;
    while let Ok(Stamped { message, .. }) = rx.recv() {
        let result = match &message {
            Ros2Message::Scan(m) => p.scan.publish(body(m)),
            Ros2Message::Pose(m) => p.pose.publish(body(m.as_ref())),
            Ros2Message::Odometry(m) => p.odom.publish(body(m.as_ref())),
            Ros2Message::Tf(m) => p.tf.publish(body(m)),
            Ros2Message::TfStatic(m) => p.tf_static.publish(body(m)),
            // Rendered here, off the loop.
            Ros2Message::Map(m) => match grid_message(m) {
                Some(grid) => p.map.publish(body(&grid)),
                None => Ok(()),
            },
        };
        if result.is_err() {
            failures += 1;
            if failures == 1 {
                warn!("a ROS 2 message could not be published (a reader too slow?)");
            }
        }
    }
}
