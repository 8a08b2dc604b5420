//! `LineBase` over real streams: TCP on 127.0.0.1 against a fake base in a
//! thread, and a serial port over a pseudo-terminal pair.
#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::thread;
use std::time::{Duration, Instant};

use clsmap_base::{BaseAdapter, BaseError, BasePose, Health, LineBase, LineStream, Twist};

/// Generous: other builds share the machine.
const DEADLINE: Duration = Duration::from_secs(10);

/// Advances `b` on a clock starting at 0 s and polls until `done` holds.
fn poll_until<S: LineStream>(
    b: &mut LineBase<S>,
    start: Instant,
    mut done: impl FnMut(&mut LineBase<S>, Option<clsmap_base::OdometrySample>) -> bool,
) {
    loop {
        b.advance(start.elapsed().as_secs_f64());
        let o = b.odometry();
        if done(b, o) {
            return;
        }
        assert!(start.elapsed() < DEADLINE, "timed out: {b:?}");
        thread::sleep(Duration::from_millis(2));
    }
}

/// Accepts one client and hands it to `f`.
fn fake_base<T: Send + 'static>(
    f: impl FnOnce(TcpStream) -> T + Send + 'static,
) -> (String, thread::JoinHandle<T>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let handle = thread::spawn(move || f(listener.accept().unwrap().0));
    (addr, handle)
}

/// Reads `n` lines (without terminators) from `r`.
fn read_lines(r: &mut impl BufRead, n: usize) -> Vec<String> {
    (0..n)
        .map(|_| {
            let mut s = String::new();
            r.read_line(&mut s).unwrap();
            s.trim_end().to_owned()
        })
        .collect()
}

#[test]
fn tcp_odometry_health_and_commands() {
    let (addr, base) = fake_base(|mut s| {
        s.write_all(b"HEALTH OK\nODOM 1.00 0.5 0.25 0.1\n").unwrap();
        let mut r = BufReader::new(s.try_clone().unwrap());
        let mut got = read_lines(&mut r, 3);
        s.write_all(b"HEALTH FAULT emergency stop\n").unwrap();
        // Remaining lines until the adapter is dropped and closes.
        let mut rest = String::new();
        r.read_to_string(&mut rest).unwrap();
        got.extend(rest.lines().map(str::to_owned));
        got
    });
    let start = Instant::now();
    let mut b = LineBase::connect_tcp(&addr, Duration::from_secs(2)).unwrap();
    assert_eq!(b.link_name(), format!("tcp {addr}"));
    let mut sample = None;
    let mut stamp = f64::NAN;
    poll_until(&mut b, start, |_, o| {
        stamp = start.elapsed().as_secs_f64();
        sample = o;
        o.is_some()
    });
    let o = sample.unwrap();
    assert_eq!(o.pose, BasePose::new(0.5, 0.25, 0.1));
    assert!(
        o.t <= stamp && o.t > 0.0,
        "stamped with the daemon clock: {o:?}"
    );
    assert_eq!(b.last_base_time(), Some(1.0));
    assert_eq!(b.health(), Health::Ok);

    let now = start.elapsed().as_secs_f64();
    b.command(Twist::new(0.2, 0.0, 0.1), now).unwrap();
    b.command(Twist::new(0.0, -0.1, 0.0), now + 0.02).unwrap();
    b.stop(now + 0.04).unwrap();
    poll_until(&mut b, start, |b, _| b.health() != Health::Ok);
    assert_eq!(
        b.health(),
        Health::Failed(format!("tcp {addr}: base reports FAULT: emergency stop"))
    );
    drop(b);
    assert_eq!(
        base.join().unwrap(),
        ["VEL 0.2 0 0.1", "VEL 0 -0.1 0", "STOP", "STOP"],
        "the last STOP is sent on drop"
    );
}

#[test]
fn tcp_malformed_line_keeps_the_link() {
    let (addr, base) = fake_base(|mut s| {
        s.write_all(b"ODOM 1 0 0 0\nBOGUS 12 x\nODOM 2 3 0 0\n")
            .unwrap();
        read_lines(&mut BufReader::new(s), 1)
    });
    let start = Instant::now();
    let mut b = LineBase::connect_tcp(&addr, Duration::from_secs(2)).unwrap();
    poll_until(&mut b, start, |_, o| o.is_some_and(|o| o.pose.x == 3.0));
    assert_eq!(b.stats().malformed_lines, 1);
    assert_eq!(b.stats().odometry_received, 2);
    let Health::Degraded(msg) = b.health() else {
        panic!("{:?}", b.health())
    };
    assert!(msg.contains("\"BOGUS 12 x\""), "{msg}");
    b.command(Twist::new(0.1, 0.0, 0.0), start.elapsed().as_secs_f64())
        .unwrap();
    assert_eq!(base.join().unwrap(), ["VEL 0.1 0 0"]);
}

#[test]
fn tcp_peer_closing_fails_the_link() {
    let (addr, base) = fake_base(|mut s| s.write_all(b"ODOM 1 1 0 0\n").unwrap());
    let start = Instant::now();
    let mut b = LineBase::connect_tcp(&addr, Duration::from_secs(2)).unwrap();
    base.join().unwrap(); // the fake base has closed its end
    let mut samples = 0;
    poll_until(&mut b, start, |b, o| {
        samples += usize::from(o.is_some());
        matches!(b.health(), Health::Failed(_))
    });
    assert_eq!(samples, 1, "data sent before the close is delivered");
    let Health::Failed(msg) = b.health() else {
        unreachable!()
    };
    assert_eq!(
        msg,
        format!("tcp {addr}: read failed: peer closed the connection")
    );
    assert_eq!(
        b.command(Twist::ZERO, start.elapsed().as_secs_f64()),
        Err(BaseError::Link(msg))
    );
}

#[test]
fn tcp_connect_errors_name_the_address() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    drop(listener); // nothing listens there now
    let Err(BaseError::Link(e)) = LineBase::connect_tcp(&addr, Duration::from_secs(2)) else {
        panic!("connect to a closed port succeeded")
    };
    assert!(
        e.contains(&format!("cannot connect to base at {addr}")),
        "{e}"
    );

    let Err(BaseError::Link(e)) = LineBase::connect_tcp("no-port-here", Duration::from_secs(1))
    else {
        panic!("bad address accepted")
    };
    assert!(e.contains("\"no-port-here\""), "{e}");
}

#[test]
fn serial_over_a_pty_pair() {
    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    let path = serialport::SerialPort::name(&slave).unwrap();
    let start = Instant::now();
    let mut b = LineBase::open_serial(Path::new(&path), 115_200).unwrap();
    assert_eq!(b.link_name(), format!("serial {path}"));
    drop(slave); // the adapter has its own descriptor

    master
        .write_all(b"ODOM 3.5 -1 2 0.5\r\nHEALTH OK\r\n")
        .unwrap();
    let mut sample = None;
    poll_until(&mut b, start, |_, o| {
        sample = o;
        o.is_some()
    });
    assert_eq!(sample.unwrap().pose, BasePose::new(-1.0, 2.0, 0.5));
    assert_eq!(b.health(), Health::Ok);

    b.command(Twist::new(0.25, 0.0, -0.5), start.elapsed().as_secs_f64())
        .unwrap();
    let mut received = Vec::new();
    let mut buf = [0u8; 64];
    while !received.ends_with(b"\n") {
        assert!(start.elapsed() < DEADLINE, "no command on the pty");
        match master.read(&mut buf) {
            Ok(n) => received.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => panic!("pty read: {e}"),
        }
    }
    assert_eq!(received, b"VEL 0.25 0 -0.5\n");

    drop(master); // hang-up
    poll_until(&mut b, start, |b, _| {
        matches!(b.health(), Health::Failed(_))
    });
    assert!(matches!(
        b.stop(start.elapsed().as_secs_f64()),
        Err(BaseError::Link(e)) if e.starts_with(&format!("serial {path}: read failed"))
    ));
}

#[test]
fn serial_open_errors_name_the_path() {
    let path = Path::new("/dev/clsmap-no-such-serial-port");
    let Err(BaseError::Link(e)) = LineBase::open_serial(path, 115_200) else {
        panic!("opened a missing port")
    };
    assert!(e.contains("/dev/clsmap-no-such-serial-port"), "{e}");
    assert!(e.contains("115200 Bd"), "{e}");
    let Err(BaseError::Link(e)) = LineBase::open_serial(path, 0) else {
        panic!("accepted 0 Bd")
    };
    assert!(e.contains("baud rate must be positive"), "{e}");
}
