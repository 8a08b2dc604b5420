//! [`Ros2Base`]: a mobile base driven by its own ROS 2 driver — odometry
//! from the driver's `nav_msgs/Odometry` topic (or its `odom` → `base_link`
//! transform on `/tf`), velocity commands to its `geometry_msgs/Twist`
//! topic, health from the odometry's age — so any base with a ROS 2 driver
//! works with clsmap, not only the line protocol.
//!
//! The DDS side (a participant and a node of its own, `<node_name>_base`)
//! runs on a thread, like the ROS 2 node's publishers: the loop hands
//! commands over without waiting and takes the odometry that arrived.
//!
//! Odometry is timed by its header stamp when that stamp is on this
//! machine's clock (within [`CLOCK_TOLERANCE`] of the arrival); a driver
//! on simulated time, or on a machine whose clock is off, is timed by the
//! arrival instead, with one warning.

use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use clsmap_base::{BaseAdapter, BaseError, BasePose, Health, OdometrySample, Twist};
use ros2_client::{
    Name, NodeName, NodeOptions, QosProfile, Subscription,
    qos::{History, WhenFull},
};
use tracing::{info, warn};

use super::config::{BaseConfig, Ros2Section};
use super::dds_sink::{CdrBody, namespace, ros2_context, type_name};
use super::handoff::Handoff;
use crate::ros2::{Odometry, RosMessage, TfMessage, Twist as RosTwist, Vector3};

/// A stamp further than this (s) from the arrival is not on this clock.
pub const CLOCK_TOLERANCE: f64 = 0.5;

/// Odometry messages held for the loop at most (a few seconds at 50 Hz).
const SAMPLES: usize = 256;
/// Commands in flight to the DDS thread at most.
const COMMANDS: usize = 64;
/// How often the DDS thread looks for odometry while no command comes.
const LISTEN_EVERY: Duration = Duration::from_millis(5);
/// Longest a reliable command write waits for a slow reader.
const WRITE_WAIT: Duration = Duration::from_millis(20);
/// How long the node stays after its last command, for DDS to send it.
const LINGER: Duration = Duration::from_millis(150);

/// An odometry message as it arrived: its stamp (s since the epoch), the
/// pose, and the arrival (daemon clock, s).
#[derive(Debug, Clone, Copy)]
struct Arrival {
    stamp: f64,
    pose: BasePose,
    at: f64,
}

/// A base behind a ROS 2 driver; see the module documentation.
#[derive(Debug)]
pub struct Ros2Base {
    samples: Receiver<Arrival>,
    commands: Handoff<Twist>,
    thread: Option<JoinHandle<Result<(), String>>>,
    /// Why the DDS side ended, once it has.
    failed: Option<String>,
    /// Wall clock (s since the epoch) at the daemon clock's zero.
    epoch: f64,
    now: f64,
    last_arrival: Option<f64>,
    stale_after: f64,
    odom_topic: String,
    clock_warned: bool,
}

/// `/a/b/odom` as ros2-client's name: namespace `/a/b`, base `odom`.
fn topic_name(topic: &str) -> Result<Name, String> {
    let (ns, base) = topic.rsplit_once('/').unwrap_or(("", topic));
    let ns = if ns.is_empty() { "/" } else { ns };
    Name::new(ns, base).map_err(|e| format!("topic {topic}: {e:?}"))
}

/// A header stamp (s since the epoch) as the daemon clock's time, when it
/// is on this clock: within [`CLOCK_TOLERANCE`] of the arrival `at`
/// (daemon clock, s; `epoch` is the wall clock at its zero), and never
/// after the arrival. `None` for a zero stamp or another clock.
fn stamp_on_this_clock(stamp: f64, epoch: f64, at: f64) -> Option<f64> {
    let t = stamp - epoch;
    (stamp > 0.0 && (t - at).abs() <= CLOCK_TOLERANCE).then_some(t.min(at))
}

impl Ros2Base {
    /// Joins DDS as `ros2` says and finds the driver's topics as `base`
    /// names them; `t0` is the daemon clock's zero and `epoch` the wall
    /// clock then (s since the epoch). Returns at once: the node is made
    /// on its thread (the loop never waits for DDS), and a node that
    /// cannot be made ends the thread, which [`BaseAdapter::link_lost`]
    /// then reports.
    pub fn start(
        ros2: &Ros2Section,
        base: &BaseConfig,
        t0: Instant,
        epoch: f64,
    ) -> Result<Ros2Base, String> {
        let (samples_tx, samples) = sync_channel(SAMPLES);
        let (commands, commands_rx) = Handoff::new(COMMANDS, "the ROS 2 base");
        let source = match base.odom_from_tf {
            true => OdometrySource::Tf {
                odom: ros2.odom_frame.clone(),
                base: ros2.base_frame.clone(),
            },
            false => OdometrySource::Topic(base.odom_topic.clone()),
        };
        let described = source.describe();
        let (ros2, cmd_topic) = (ros2.clone(), base.cmd_vel_topic.clone());
        let thread = std::thread::Builder::new()
            .name("clsmap-ros2-base".into())
            .spawn(move || run_node(&ros2, &source, &cmd_topic, t0, &samples_tx, &commands_rx))
            .map_err(|e| e.to_string())?;
        Ok(Ros2Base {
            samples,
            commands,
            thread: Some(thread),
            failed: None,
            epoch,
            now: 0.0,
            last_arrival: None,
            stale_after: base.stale_odometry,
            odom_topic: described,
            clock_warned: false,
        })
    }

    /// The sample's time on the daemon clock: its stamp when that is on
    /// this clock, else its arrival.
    fn time_of(&mut self, a: &Arrival) -> f64 {
        if let Some(t) = stamp_on_this_clock(a.stamp, self.epoch, a.at) {
            return t;
        }
        let stamped = a.stamp - self.epoch;
        if !self.clock_warned {
            self.clock_warned = true;
            warn!(
                topic = %self.odom_topic,
                off_s = stamped - a.at,
                "odometry stamps are not on this machine's clock (simulated time, or a clock \
                 off): timed by arrival instead"
            );
        }
        a.at
    }

    fn send(&mut self, twist: Twist) -> Result<(), BaseError> {
        if let Some(e) = &self.failed {
            return Err(BaseError::Link(e.clone()));
        }
        self.commands.send(twist);
        Ok(())
    }

    /// Notices a DDS thread that ended.
    fn check_thread(&mut self) {
        if self.failed.is_none() && self.thread.as_ref().is_some_and(JoinHandle::is_finished) {
            let why = match self.thread.take().map(JoinHandle::join) {
                Some(Ok(Err(e))) => e,
                _ => "the ROS 2 base's thread ended".into(),
            };
            warn!("ROS 2 base: {why}");
            self.failed = Some(why);
        }
    }
}

impl Drop for Ros2Base {
    fn drop(&mut self) {
        // A stop last; the thread sends what is queued, then ends.
        self.commands.send(Twist::ZERO);
        self.commands.close();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl BaseAdapter for Ros2Base {
    fn advance(&mut self, now: f64) {
        self.now = now;
        self.check_thread();
    }

    fn odometry(&mut self) -> Option<OdometrySample> {
        let a = self.samples.try_recv().ok()?;
        self.last_arrival = Some(a.at);
        let t = self.time_of(&a);
        Some(OdometrySample { t, pose: a.pose })
    }

    fn command(&mut self, twist: Twist, _now: f64) -> Result<(), BaseError> {
        if !(twist.vx.is_finite() && twist.vy.is_finite() && twist.omega.is_finite()) {
            self.send(Twist::ZERO)?;
            return Err(BaseError::InvalidCommand(format!("{twist:?}")));
        }
        self.send(twist)
    }

    fn stop(&mut self, _now: f64) -> Result<(), BaseError> {
        self.send(Twist::ZERO)
    }

    fn health(&self) -> Health {
        if let Some(e) = &self.failed {
            return Health::Failed(e.clone());
        }
        match self.last_arrival {
            None => Health::Degraded(format!("no odometry on {} yet", self.odom_topic)),
            // One message for the whole silence (the daemon logs changes).
            Some(at) if self.now - at > self.stale_after => Health::Degraded(format!(
                "no odometry on {} for more than {} s",
                self.odom_topic, self.stale_after
            )),
            Some(_) => Health::Ok,
        }
    }

    fn link_lost(&self) -> bool {
        self.failed.is_some()
    }
}

/// Where the driver's odometry comes from.
#[derive(Debug, Clone)]
enum OdometrySource {
    /// `nav_msgs/Odometry` on this topic.
    Topic(String),
    /// The transform of `base` in `odom` on `/tf`.
    Tf { odom: String, base: String },
}

impl OdometrySource {
    /// As the log names it.
    fn describe(&self) -> String {
        match self {
            OdometrySource::Topic(t) => t.clone(),
            OdometrySource::Tf { odom, base } => format!("/tf ({odom} → {base})"),
        }
    }
}

/// The subscription of an [`OdometrySource`].
enum OdometryReader {
    Topic(Subscription<Odometry>),
    Tf {
        reader: Subscription<TfMessage>,
        odom: String,
        base: String,
    },
}

impl OdometryReader {
    /// The next odometry pose and its stamp (s since the epoch), if one
    /// came; `Err` when a message could not be read.
    fn take(&self) -> Result<Option<(f64, BasePose)>, String> {
        let pose = |p: &Vector3, q: &crate::ros2::Quaternion| BasePose {
            x: p.x,
            y: p.y,
            theta: q.yaw(),
        };
        match self {
            OdometryReader::Topic(r) => match r.take() {
                Ok(Some((m, _))) => Ok(Some((
                    m.header.stamp.as_secs(),
                    pose(&m.pose.position, &m.pose.orientation),
                ))),
                Ok(None) => Ok(None),
                Err(e) => Err(format!("{e:?}")),
            },
            OdometryReader::Tf { reader, odom, base } => loop {
                match reader.take() {
                    Ok(Some((m, _))) => {
                        let frame = |f: &str| f.trim_start_matches('/').to_string();
                        let found = m.transforms.iter().find(|t| {
                            frame(&t.header.frame_id) == *odom && frame(&t.child_frame_id) == *base
                        });
                        if let Some(t) = found {
                            return Ok(Some((
                                t.header.stamp.as_secs(),
                                pose(&t.translation, &t.rotation),
                            )));
                        }
                    }
                    Ok(None) => return Ok(None),
                    Err(e) => return Err(format!("{e:?}")),
                }
            },
        }
    }
}

fn run_node(
    ros2: &Ros2Section,
    source: &OdometrySource,
    cmd_topic: &str,
    t0: Instant,
    samples: &SyncSender<Arrival>,
    commands: &Receiver<Twist>,
) -> Result<(), String> {
    let started = (|| {
        let context = ros2_context(ros2)?;
        let mut node = context
            .new_node(
                NodeName::new(namespace(ros2), &format!("{}_base", ros2.node_name))
                    .map_err(|e| format!("node name: {e:?}"))?,
                NodeOptions::new()
                    .enable_rosout(false)
                    .start_parameter_services(false),
            )
            .map_err(|e| format!("node: {e:?}"))?;
        // A best-effort reader matches reliable and best-effort drivers; a
        // reliable writer matches either kind of reader.
        let listen = QosProfile::subscription_default().history(History::KeepLast { depth: 50 });
        let (name, ty) = match source {
            OdometrySource::Topic(t) => (t.as_str(), Odometry::TYPE),
            OdometrySource::Tf { .. } => ("/tf", TfMessage::TYPE),
        };
        let topic = node
            .create_topic(&topic_name(name)?, type_name(ty), &listen)
            .map_err(|e| format!("topic {name}: {e:?}"))?;
        let odom = match source {
            OdometrySource::Topic(_) => OdometryReader::Topic(
                node.create_subscription::<Odometry>(&topic, Some(listen))
                    .map_err(|e| format!("subscription: {e:?}"))?,
            ),
            OdometrySource::Tf { odom, base } => OdometryReader::Tf {
                reader: node
                    .create_subscription::<TfMessage>(&topic, Some(listen))
                    .map_err(|e| format!("subscription: {e:?}"))?,
                odom: odom.clone(),
                base: base.clone(),
            },
        };
        let talk = QosProfile::publisher_default()
            .reliability_reliable(WhenFull::Wait(WRITE_WAIT))
            .history(History::KeepLast { depth: 10 });
        let cmd = node
            .create_topic(&topic_name(cmd_topic)?, type_name(RosTwist::TYPE), &talk)
            .map_err(|e| format!("topic {cmd_topic}: {e:?}"))?;
        let cmd = node
            .create_publisher::<CdrBody>(&cmd, Some(talk))
            .map_err(|e| format!("publisher: {e:?}"))?;
        Ok::<_, String>((node, odom, cmd))
    })();
    let (_node, odom, cmd) = started?;
    info!(topic = cmd_topic, "ROS 2 base: node up");
    let (mut refused, mut unreadable) = (0u64, 0u64);
    loop {
        match commands.recv_timeout(LISTEN_EVERY) {
            Ok(t) => {
                let twist = RosTwist {
                    linear: Vector3 {
                        x: t.vx,
                        y: t.vy,
                        z: 0.0,
                    },
                    angular: Vector3 {
                        x: 0.0,
                        y: 0.0,
                        z: t.omega,
                    },
                };
                if cmd.publish(CdrBody::of(twist.to_cdr())).is_err() {
                    refused += 1;
                    if refused == 1 {
                        warn!(topic = cmd_topic, "a velocity command could not be sent");
                    }
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                // The last command (the stop) is sent; DDS sends on its
                // own threads, so give it a moment before the node goes.
                std::thread::sleep(LINGER);
                return Ok(());
            }
        }
        loop {
            match odom.take() {
                Ok(Some((stamp, pose))) => {
                    let arrival = Arrival {
                        stamp,
                        pose,
                        at: t0.elapsed().as_secs_f64(),
                    };
                    // A full queue drops (the loop polls at 50 Hz); a
                    // non-finite pose is refused and counted by the loop.
                    match samples.try_send(arrival) {
                        Ok(()) | Err(TrySendError::Full(_)) => {}
                        Err(TrySendError::Disconnected(_)) => return Ok(()),
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    unreadable += 1;
                    if unreadable.is_power_of_two() {
                        warn!(
                            count = unreadable,
                            "odometry messages could not be read: {e}"
                        );
                    }
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn stamps_time_odometry_only_when_on_this_clock() {
        let epoch = 1_700_000_000.0;
        // 30 ms on the wire.
        assert_eq!(stamp_on_this_clock(epoch + 10.0, epoch, 10.03), Some(10.0));
        // A clock a little ahead never puts a sample after its arrival.
        assert_eq!(stamp_on_this_clock(epoch + 10.2, epoch, 10.0), Some(10.0));
        // Simulated time, an unset stamp, a clock a minute off.
        assert_eq!(stamp_on_this_clock(125.0, epoch, 10.0), None);
        assert_eq!(stamp_on_this_clock(0.0, epoch, 10.0), None);
        assert_eq!(stamp_on_this_clock(epoch + 70.0, epoch, 10.0), None);
    }

    #[test]
    fn topics_split_into_namespace_and_name() {
        assert_eq!(topic_name("/odom").unwrap().to_string(), "/odom");
        assert_eq!(
            topic_name("/robot1/base/odom").unwrap().to_string(),
            "/robot1/base/odom"
        );
    }
}
