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
//! `/map` and `/cls_map` are transient-local, so a subscriber that joins
//! late still gets them. When the base is a ROS 2 node
//! ([`super::ros2_base`]), its driver owns `/odom` and `/cmd_vel`: the node
//! then neither publishes the one nor listens to the other.

use std::sync::mpsc::{Receiver, RecvTimeoutError, sync_channel};
use std::thread::JoinHandle;
use std::time::Duration;

use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher,
    QosProfile, Subscription,
    qos::{Durability, History, WhenFull},
};
use serde::ser::{Serialize, SerializeTuple, Serializer};
use tracing::{info, warn};

use super::config::Ros2Section;
use super::handoff::Handoff;
use super::ros2_out::{ODOM_TOPIC, Ros2Message, Stamped, TOPICS, for_dds};
use crate::geometry::Pose2;
use crate::ros2::{PoseWithCovarianceStamped, RosMessage, Twist};

/// What the node hears and hands to the loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Ros2Command {
    /// `/cmd_vel`: drive (base frame, m/s, rad/s).
    Velocity(clsmap_base::Twist),
    /// `/initialpose` (RViz's "2D Pose Estimate"): the robot is about here
    /// (map frame).
    PoseHint(Pose2),
}

/// How often the node looks for incoming messages (s) while no message
/// goes out.
const LISTEN_EVERY: Duration = Duration::from_millis(20);

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
pub(super) struct CdrBody(Vec<u8>);

impl CdrBody {
    /// `cdr` (a message as [`crate::ros2::msg`] writes it) without its
    /// 4-byte encapsulation header, which the DDS stack writes itself.
    pub(super) fn of(mut cdr: Vec<u8>) -> CdrBody {
        cdr.drain(..4.min(cdr.len()));
        CdrBody(cdr)
    }
}

impl Serialize for CdrBody {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(self.0.len())?;
        for b in &self.0 {
            t.serialize_element(b)?;
        }
        t.end()
    }
}

/// The node's publishers (in [`TOPICS`] order; `None` for one it leaves
/// to the base's driver) and subscriptions.
struct Publishers {
    topics: Vec<Option<Publisher<CdrBody>>>,
    cmd_vel: Option<Subscription<Twist>>,
    initial_pose: Subscription<PoseWithCovarianceStamped>,
    map_frame: String,
    base_frame: String,
    base_is_ros2: bool,
    /// Kept alive while publishing.
    _node: Node,
}

/// The ROS 2 node, publishing.
#[derive(Debug)]
pub struct DdsSink {
    queue: Handoff<Stamped>,
    thread: Option<JoinHandle<()>>,
}

/// `pkg/msg/Type` as ros2-client's type name.
pub(super) fn type_name(full: &str) -> MessageTypeName {
    let mut parts = full.split('/');
    let package = parts.next().unwrap_or_default();
    let name = parts.next_back().unwrap_or_default();
    MessageTypeName::new(package, name)
}

/// A DDS participant as `cfg` says: its domain, and only the loopback
/// interface with `localhost_only`.
pub fn ros2_context(cfg: &Ros2Section) -> Result<Context, String> {
    if cfg.localhost_only {
        let participant = ros2_client::dds::rustdds::DomainParticipantBuilder::new(cfg.domain_id)
            .with_only_networks([std::net::Ipv4Addr::LOCALHOST])
            .build()
            .map_err(|e| format!("DDS participant: {e:?}"))?;
        Context::from_domain_participant(participant)
    } else {
        Context::with_options(ContextOptions::new().domain_id(cfg.domain_id))
    }
    .map_err(|e| format!("DDS participant: {e:?}"))
}

/// The node's namespace as ros2-client takes it.
pub fn namespace(cfg: &Ros2Section) -> &str {
    if cfg.namespace.is_empty() {
        "/"
    } else {
        cfg.namespace.as_str()
    }
}

fn start_node(cfg: &Ros2Section, base_is_ros2: bool) -> Result<Publishers, String> {
    let context = ros2_context(cfg)?;
    let namespace = namespace(cfg);
    let mut node = context
        .new_node(
            NodeName::new(namespace, &cfg.node_name).map_err(|e| format!("node name: {e:?}"))?,
            NodeOptions::new()
                .enable_rosout(false)
                .start_parameter_services(false),
        )
        .map_err(|e| format!("node: {e:?}"))?;
    let mut topics = Vec::with_capacity(TOPICS.len());
    for (i, t) in TOPICS.iter().enumerate() {
        if base_is_ros2 && i == ODOM_TOPIC {
            topics.push(None);
            continue;
        }
        let qos = QosProfile::publisher_default()
            .reliability_reliable(WhenFull::Wait(WRITE_WAIT))
            .durability(if t.latched {
                Durability::TransientLocal
            } else {
                Durability::Volatile
            })
            .history(History::KeepLast { depth: t.depth });
        let name = Name::new(namespace, t.name).map_err(|e| format!("topic {}: {e:?}", t.name))?;
        let topic = node
            .create_topic(&name, type_name(t.type_name), &qos)
            .map_err(|e| format!("topic {}: {e:?}", t.name))?;
        topics.push(Some(
            node.create_publisher::<CdrBody>(&topic, Some(qos))
                .map_err(|e| format!("publisher: {e:?}"))?,
        ));
    }
    // Best-effort readers match reliable and best-effort writers alike
    // (teleop tools and RViz use either).
    let listen = QosProfile::subscription_default().history(History::KeepLast { depth: 10 });
    let subscription = |topic: &str, ty: &str| {
        let name = Name::new(namespace, topic).map_err(|e| format!("topic {topic}: {e:?}"))?;
        node.create_topic(&name, type_name(ty), &listen)
            .map_err(|e| format!("topic {topic}: {e:?}"))
    };
    let cmd_vel_topic = subscription("cmd_vel", Twist::TYPE)?;
    let initial_pose_topic = subscription("initialpose", PoseWithCovarianceStamped::TYPE)?;
    let cmd_vel = match base_is_ros2 {
        true => None,
        false => Some(
            node.create_subscription::<Twist>(&cmd_vel_topic, Some(listen.clone()))
                .map_err(|e| format!("subscription: {e:?}"))?,
        ),
    };
    let initial_pose = node
        .create_subscription::<PoseWithCovarianceStamped>(&initial_pose_topic, Some(listen))
        .map_err(|e| format!("subscription: {e:?}"))?;
    Ok(Publishers {
        topics,
        cmd_vel,
        initial_pose,
        map_frame: cfg.map_frame.clone(),
        base_frame: cfg.base_frame.clone(),
        base_is_ros2,
        _node: node,
    })
}

impl DdsSink {
    /// Starts the node as `cfg` says (leaving `/odom` and `/cmd_vel` to
    /// the base's driver when `base_is_ros2`); returns once its publishers
    /// exist. What it hears goes to `inbox`.
    pub fn start(
        cfg: &Ros2Section,
        base_is_ros2: bool,
        inbox: tokio::sync::mpsc::UnboundedSender<Ros2Command>,
    ) -> Result<DdsSink, DdsError> {
        let (queue, rx) = Handoff::new(QUEUE, "the ROS 2 node");
        let (ready_tx, ready_rx) = sync_channel::<Result<(), String>>(1);
        let cfg = cfg.clone();
        let thread = std::thread::Builder::new()
            .name("clsmap-ros2".into())
            .spawn(move || match start_node(&cfg, base_is_ros2) {
                Ok(p) => {
                    let _ = ready_tx.send(Ok(()));
                    run_node(&p, &rx, &inbox);
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
        let published: Vec<String> = TOPICS
            .iter()
            .enumerate()
            .filter(|&(i, _)| !(base_is_ros2 && i == ODOM_TOPIC))
            .map(|(_, t)| format!("/{}", t.name))
            .collect();
        info!(
            "ROS 2 node up: publishing {}, listening to {}/initialpose",
            published.join(" "),
            if base_is_ros2 { "" } else { "/cmd_vel " }
        );
        Ok(DdsSink {
            queue,
            thread: Some(thread),
        })
    }

    /// Hands `messages` to the node without waiting.
    pub fn send(&mut self, messages: &[Stamped]) {
        for m in messages {
            self.queue.send(m.clone());
        }
    }

    /// Stops the node.
    pub fn finish(mut self) {
        self.queue.close();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn run_node(
    p: &Publishers,
    rx: &Receiver<Stamped>,
    inbox: &tokio::sync::mpsc::UnboundedSender<Ros2Command>,
) {
    let mut failures = 0u64;
    loop {
        match rx.recv_timeout(LISTEN_EVERY) {
            Ok(Stamped { message, .. }) => {
                if publish(p, &message).is_err() {
                    failures += 1;
                    if failures == 1 {
                        warn!("a ROS 2 message could not be published (a reader too slow?)");
                    }
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => return,
        }
        while let Some(Ok(Some((t, _)))) = p.cmd_vel.as_ref().map(Subscription::take) {
            let twist = clsmap_base::Twist {
                vx: t.linear.x,
                vy: t.linear.y,
                omega: t.angular.z,
            };
            if inbox.send(Ros2Command::Velocity(twist)).is_err() {
                return;
            }
        }
        while let Ok(Some((m, _))) = p.initial_pose.take() {
            let frame = m.header.frame_id.trim_start_matches('/');
            if !(frame.is_empty() || frame == p.map_frame) {
                warn!(frame, "a pose hint not in the map frame is ignored");
                continue;
            }
            let q = &m.pose;
            let pose = Pose2::new(q.position.x, q.position.y, q.orientation.yaw());
            if inbox.send(Ros2Command::PoseHint(pose)).is_err() {
                return;
            }
        }
    }
}

fn publish(p: &Publishers, message: &Ros2Message) -> Result<(), ()> {
    let Some(message) = for_dds(message, p.base_is_ros2, &p.base_frame) else {
        return Ok(());
    };
    // Rendered (a map's grid) and encoded here, off the loop.
    let (Some(cdr), Some(Some(publisher))) =
        (message.encode(), p.topics.get(message.topic_index()))
    else {
        return Ok(());
    };
    publisher.publish(CdrBody::of(cdr)).map_err(|_| ())
}
