use super::*;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

/// In-memory stream: scripted reads, recorded writes.
#[derive(Debug, Default, Clone)]
struct Script {
    reads: Arc<Mutex<VecDeque<io::Result<Vec<u8>>>>>,
    written: Arc<Mutex<Vec<u8>>>,
    fail_writes: Arc<Mutex<bool>>,
}

impl Script {
    fn feed(&self, bytes: &[u8]) {
        self.reads.lock().unwrap().push_back(Ok(bytes.to_vec()));
    }
    fn break_read(&self) {
        self.reads.lock().unwrap().push_back(Err(io::Error::new(
            io::ErrorKind::ConnectionReset,
            "reset by peer",
        )));
    }
    fn written(&self) -> String {
        String::from_utf8(self.written.lock().unwrap().clone()).unwrap()
    }
}

impl LineStream for Script {
    fn read_available(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let mut reads = self.reads.lock().unwrap();
        match reads.pop_front() {
            None => Ok(0),
            Some(Err(e)) => Err(e),
            Some(Ok(mut bytes)) => {
                let n = bytes.len().min(buf.len());
                buf[..n].copy_from_slice(&bytes[..n]);
                if n < bytes.len() {
                    reads.push_front(Ok(bytes.split_off(n)));
                }
                Ok(n)
            }
        }
    }
    fn write_all_now(&mut self, bytes: &[u8]) -> io::Result<()> {
        if *self.fail_writes.lock().unwrap() {
            return Err(io::Error::new(io::ErrorKind::BrokenPipe, "broken pipe"));
        }
        self.written.lock().unwrap().extend_from_slice(bytes);
        Ok(())
    }
}

fn base() -> (LineBase<Script>, Script) {
    let s = Script::default();
    (LineBase::new(s.clone(), "test link"), s)
}

#[test]
fn nothing_is_read_before_the_clock_is_known() {
    let (mut b, s) = base();
    s.feed(b"ODOM 1 0 0 0\n");
    assert_eq!(b.odometry(), None);
    assert_eq!(b.stats().odometry_received, 0);
    b.advance(7.0);
    let o = b.odometry().unwrap();
    assert_eq!(o.t, 7.0, "stamped with the daemon clock, not the base's");
    assert_eq!(b.last_base_time(), Some(1.0));
}

#[test]
fn trait_advance_stamps_samples() {
    let s = Script::default();
    let mut b: Box<dyn BaseAdapter + Send> = Box::new(LineBase::new(s.clone(), "boxed"));
    s.feed(b"ODOM 1 0.5 0 0\n");
    assert_eq!(b.odometry(), None);
    b.advance(3.25);
    assert_eq!(b.odometry().unwrap().t, 3.25);
}

#[test]
fn newest_sample_wins_and_is_returned_once() {
    let (mut b, s) = base();
    b.advance(100.0);
    s.feed(b"ODOM 10.00 0.1 0 0\nODOM 10.02 0.2 0 0\nODOM 10.0");
    s.feed(b"4 0.3 0.5 4.0\nHEALTH OK\n");
    let o = b.odometry().unwrap();
    assert_eq!(o.t, 100.0);
    assert_eq!(o.pose, BasePose::new(0.3, 0.5, 4.0));
    assert!(o.pose.theta < 0.0, "heading wrapped to (-pi, pi]");
    assert_eq!(b.odometry(), None);
    assert_eq!(
        b.stats(),
        LineBaseStats {
            odometry_received: 3,
            odometry_skipped: 2,
            ..LineBaseStats::default()
        }
    );
    assert_eq!(b.health(), Health::Ok);
}

#[test]
fn repeated_or_older_base_times_are_dropped() {
    let (mut b, s) = base();
    b.advance(1.0);
    s.feed(b"ODOM 5 1 0 0\n");
    assert_eq!(b.odometry().unwrap().pose.x, 1.0);
    b.advance(1.02);
    s.feed(b"ODOM 5 2 0 0\nODOM 4.9 3 0 0\n");
    assert_eq!(b.odometry(), None);
    assert_eq!(b.stats().odometry_out_of_order, 2);
    let Health::Degraded(msg) = b.health() else {
        panic!("{:?}", b.health())
    };
    assert!(msg.contains("4.9") && msg.contains("not after"), "{msg}");
    b.advance(1.04);
    s.feed(b"ODOM 5.02 4 0 0\n");
    assert_eq!(b.odometry().unwrap().pose.x, 4.0);
}

#[test]
fn malformed_line_degrades_health_with_its_text_for_a_while() {
    let (mut b, s) = base();
    b.advance(0.0);
    s.feed(b"ODOM 1 2 oops 3\r\nODOM 1 0.5 0 0\n");
    assert_eq!(b.odometry().unwrap().pose.x, 0.5, "link keeps working");
    assert_eq!(b.stats().malformed_lines, 1);
    let Health::Degraded(msg) = b.health() else {
        panic!("{:?}", b.health())
    };
    assert!(msg.contains("\"ODOM 1 2 oops 3\""), "{msg}");
    assert!(msg.contains("field y"), "{msg}");
    assert!(msg.contains("test link"), "{msg}");
    b.advance(PROBLEM_HOLD - 0.01);
    assert!(matches!(b.health(), Health::Degraded(_)));
    b.advance(PROBLEM_HOLD + 0.01);
    assert_eq!(b.health(), Health::Ok);
    assert!(b.command(Twist::new(0.1, 0.0, 0.0), 6.0).is_ok());
}

#[test]
fn over_long_line_is_reported_with_its_start_and_skipped() {
    let (mut b, s) = base();
    b.advance(0.0);
    let mut long = b"ODOM ".to_vec();
    long.extend(std::iter::repeat_n(b'9', 1000));
    s.feed(&long);
    s.feed(b" 0 0 0\nODOM 2 1 1 0\n");
    assert_eq!(b.odometry().unwrap().pose.x, 1.0);
    assert_eq!(b.stats().malformed_lines, 1);
    let Health::Degraded(msg) = b.health() else {
        panic!("{:?}", b.health())
    };
    assert!(msg.contains("longer than"), "{msg}");
    assert!(msg.contains("\"ODOM 999"), "{msg}");
    assert!(msg.len() < 300, "echo is bounded: {msg}");
}

#[test]
fn base_fault_fails_health_until_ok() {
    let (mut b, s) = base();
    b.advance(0.0);
    s.feed(b"HEALTH FAULT bumper pressed\n");
    assert_eq!(b.odometry(), None);
    assert_eq!(
        b.health(),
        Health::Failed("test link: base reports FAULT: bumper pressed".to_owned())
    );
    s.feed(b"HEALTH OK\n");
    let _ = b.odometry();
    assert_eq!(b.health(), Health::Ok);
}

#[test]
fn commands_are_encoded() {
    let (mut b, s) = base();
    b.command(Twist::new(0.3, -0.1, 0.5), 1.0).unwrap();
    b.stop(1.02).unwrap();
    assert!(matches!(
        b.command(Twist::new(0.0, f64::INFINITY, 0.0), 1.04),
        Err(BaseError::InvalidCommand(_))
    ));
    assert_eq!(s.written(), "VEL 0.3 -0.1 0.5\nSTOP\nSTOP\n");
    drop(b);
    assert_eq!(
        s.written(),
        "VEL 0.3 -0.1 0.5\nSTOP\nSTOP\nSTOP\n",
        "STOP on drop"
    );
}

#[test]
fn read_error_latches_failure() {
    let (mut b, s) = base();
    b.advance(0.0);
    s.feed(b"ODOM 1 1 0 0\n");
    s.break_read();
    s.feed(b"ODOM 2 2 0 0\n");
    // The sample decoded before the error is still delivered.
    assert_eq!(b.odometry().unwrap().pose.x, 1.0);
    assert_eq!(b.odometry(), None, "nothing is read after the failure");
    let Health::Failed(msg) = b.health() else {
        panic!("{:?}", b.health())
    };
    assert!(
        msg.contains("test link: read failed: reset by peer"),
        "{msg}"
    );
    let Err(BaseError::Link(e)) = b.command(Twist::ZERO, 0.1) else {
        panic!("expected a link error")
    };
    assert_eq!(e, msg);
    assert!(matches!(b.stop(0.2), Err(BaseError::Link(_))));
    drop(b);
    assert_eq!(s.written(), "", "nothing written on a failed link");
}

#[test]
fn write_error_latches_failure() {
    let (mut b, s) = base();
    *s.fail_writes.lock().unwrap() = true;
    let Err(BaseError::Link(e)) = b.stop(0.0) else {
        panic!("expected a link error")
    };
    assert!(e.contains("write failed: broken pipe"), "{e}");
    *s.fail_writes.lock().unwrap() = false;
    assert!(b.command(Twist::ZERO, 0.1).is_err(), "failure is latched");
    assert!(matches!(b.health(), Health::Failed(_)));
}

#[test]
fn flood_is_drained_in_bounded_steps() {
    let (mut b, s) = base();
    b.advance(0.0);
    let mut flood = Vec::new();
    for i in 0..20_000 {
        flood.extend_from_slice(format!("ODOM {} {i} 0 0\n", i + 1).as_bytes());
    }
    assert!(flood.len() > 2 * MAX_READ_PER_POLL);
    s.feed(&flood);
    let first = b.odometry().unwrap();
    assert!(first.pose.x < 19_999.0, "one call reads a bounded amount");
    let mut last = first;
    while let Some(o) = b.odometry() {
        last = o;
    }
    assert_eq!(last.pose.x, 19_999.0);
    assert_eq!(b.stats().odometry_received, 20_000);
    assert_eq!(b.stats().malformed_lines, 0);
}
