//! The serial port: a thin shell that moves bytes between a tty and the
//! sans-IO link. It opens the port exclusively, sets the line speed when the
//! link asks for it, and paces host bytes as the sensor wants them.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{ClearBuffer, SerialPort, TTYPort};

/// Why the serial port could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SerialError {
    #[error("{path}: no such device (is the LMS200 adapter plugged in?)")]
    NotFound { path: PathBuf },
    #[error("{path}: permission denied (add the user to the `dialout` group)")]
    PermissionDenied { path: PathBuf },
    #[error("{path}: not a serial port (tty)")]
    NotATty { path: PathBuf },
    #[error("{path}: busy, another program holds it open exclusively")]
    Busy { path: PathBuf },
    #[error("{path}: cannot set the line speed to {baud} baud: {reason}")]
    Baud {
        path: PathBuf,
        baud: u32,
        reason: String,
    },
    #[error("{path}: {what}: {source}")]
    Io {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: io::Error,
    },
    #[error("{path}: {what}: {reason}")]
    Port {
        path: PathBuf,
        what: &'static str,
        reason: String,
    },
}

/// Smallest gap between two host bytes the sensor accepts (TL §4.3: 55 µs),
/// with a margin. At 500 kBd a byte lasts 20 µs, so bytes written back to
/// back would come too close; at ≤ 38400 Bd a byte lasts ≥ 260 µs.
pub const HOST_BYTE_GAP: Duration = Duration::from_micros(60);

/// An open serial port.
#[derive(Debug)]
pub struct SerialTransport {
    port: TTYPort,
    path: PathBuf,
    baud: u32,
}

impl SerialTransport {
    /// Opens `path` exclusively at `baud`, 8N1, raw, no flow control.
    pub fn open(path: &Path, baud: u32) -> Result<Self, SerialError> {
        let owned = path.to_path_buf();
        let meta = std::fs::metadata(path).map_err(|e| match e.kind() {
            io::ErrorKind::NotFound => SerialError::NotFound {
                path: owned.clone(),
            },
            io::ErrorKind::PermissionDenied => SerialError::PermissionDenied {
                path: owned.clone(),
            },
            _ => SerialError::Io {
                path: owned.clone(),
                what: "cannot inspect the device",
                source: e,
            },
        })?;
        if !is_char_device(&meta) {
            return Err(SerialError::NotATty { path: owned });
        }
        let port = serialport::new(path.to_string_lossy(), baud)
            .timeout(Duration::from_millis(10))
            .open_native()
            .map_err(|e| open_error(&owned, e))?;
        Ok(SerialTransport {
            port,
            path: owned,
            baud,
        })
    }

    /// Wraps an already open port (for example one end of a pty pair).
    pub fn from_port(port: TTYPort, path: PathBuf) -> Result<Self, SerialError> {
        let baud = port.baud_rate().map_err(|e| SerialError::Port {
            path: path.clone(),
            what: "cannot read the line speed",
            reason: e.to_string(),
        })?;
        Ok(SerialTransport { port, path, baud })
    }

    /// The device path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The current line speed (baud).
    pub fn baud(&self) -> u32 {
        self.baud
    }

    /// Switches the host side of the line to `baud`. Bytes still in the
    /// receive buffer were sent at the old speed and are discarded.
    pub fn set_baud(&mut self, baud: u32) -> Result<(), SerialError> {
        self.port
            .set_baud_rate(baud)
            .map_err(|e| SerialError::Baud {
                path: self.path.clone(),
                baud,
                reason: e.to_string(),
            })?;
        self.baud = baud;
        Ok(())
    }

    /// Drops whatever the port has received but not yet been read.
    pub fn clear_input(&mut self) -> Result<(), SerialError> {
        self.port
            .clear(ClearBuffer::Input)
            .map_err(|e| SerialError::Port {
                path: self.path.clone(),
                what: "cannot clear the receive buffer",
                reason: e.to_string(),
            })
    }

    /// Reads what has arrived, waiting at most `timeout`; `Ok(0)` when
    /// nothing came in time.
    pub fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, SerialError> {
        // The port's timeout is the wait for the first byte; at least 1 ms
        // so that a zero deadline does not become a busy loop.
        let timeout = timeout.max(Duration::from_millis(1));
        self.port
            .set_timeout(timeout)
            .map_err(|e| SerialError::Port {
                path: self.path.clone(),
                what: "cannot set the read timeout",
                reason: e.to_string(),
            })?;
        match self.port.read(buf) {
            Ok(n) => Ok(n),
            Err(e) if e.kind() == io::ErrorKind::TimedOut => Ok(0),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => Ok(0),
            Err(e) => Err(SerialError::Io {
                path: self.path.clone(),
                what: "read failed (device unplugged?)",
                source: e,
            }),
        }
    }

    /// Writes a host telegram. Above 38400 Bd the bytes go out one by one,
    /// [`HOST_BYTE_GAP`] apart, well inside the sensor's 6 ms limit.
    pub fn write_telegram(&mut self, bytes: &[u8]) -> Result<(), SerialError> {
        let io_err = |source| SerialError::Io {
            path: self.path.clone(),
            what: "write failed (device unplugged?)",
            source,
        };
        if self.baud <= 38_400 {
            self.port.write_all(bytes).map_err(io_err)?;
            return self.port.flush().map_err(io_err);
        }
        for (i, b) in bytes.iter().enumerate() {
            let sent = Instant::now();
            self.port
                .write_all(std::slice::from_ref(b))
                .map_err(io_err)?;
            self.port.flush().map_err(io_err)?;
            if i + 1 < bytes.len() {
                let elapsed = sent.elapsed();
                if elapsed < HOST_BYTE_GAP {
                    std::thread::sleep(HOST_BYTE_GAP - elapsed);
                }
            }
        }
        Ok(())
    }

    /// The underlying port, for shells that need more than this offers.
    pub fn port_mut(&mut self) -> &mut TTYPort {
        &mut self.port
    }
}

#[cfg(unix)]
fn is_char_device(meta: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::FileTypeExt;
    meta.file_type().is_char_device()
}

#[cfg(not(unix))]
fn is_char_device(_meta: &std::fs::Metadata) -> bool {
    true
}

fn open_error(path: &Path, e: serialport::Error) -> SerialError {
    let path = path.to_path_buf();
    match e.kind() {
        serialport::ErrorKind::NoDevice => SerialError::Busy { path },
        serialport::ErrorKind::Io(io::ErrorKind::NotFound) => SerialError::NotFound { path },
        serialport::ErrorKind::Io(io::ErrorKind::PermissionDenied) => {
            SerialError::PermissionDenied { path }
        }
        // TIOCEXCL on a character device that is not a tty fails with
        // ENOTTY, whose text is "Not a typewriter" (or "Inappropriate ioctl").
        _ if e.description.contains("typewriter") || e.description.contains("ioctl") => {
            SerialError::NotATty { path }
        }
        _ => SerialError::Port {
            path,
            what: "cannot open",
            reason: e.description,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_device_is_named() {
        let err = SerialTransport::open(Path::new("/dev/does-not-exist-lms"), 9600).unwrap_err();
        assert!(matches!(err, SerialError::NotFound { .. }), "{err}");
        assert!(err.to_string().contains("/dev/does-not-exist-lms"));
    }

    #[test]
    fn regular_file_is_not_a_tty() {
        let dir = std::env::temp_dir().join(format!("lms200-serial-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("plain");
        std::fs::write(&file, b"x").unwrap();
        let err = SerialTransport::open(&file, 9600).unwrap_err();
        assert!(matches!(err, SerialError::NotATty { .. }), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn null_device_is_not_a_tty() {
        let err = SerialTransport::open(Path::new("/dev/null"), 9600).unwrap_err();
        assert!(matches!(err, SerialError::NotATty { .. }), "{err}");
    }

    #[test]
    fn pty_pair_carries_bytes_and_baud_changes_are_visible_to_the_master() {
        let (master, slave) = TTYPort::pair().unwrap();
        let slave_path = PathBuf::from(slave.name().unwrap());
        drop(slave);
        let mut host = SerialTransport::open(&slave_path, 9600).unwrap();
        let mut sensor = SerialTransport::from_port(master, PathBuf::from("pty-master")).unwrap();
        host.set_baud(500_000).unwrap();
        // On Linux the master reports the slave's termios.
        assert_eq!(sensor.port_mut().baud_rate().unwrap(), 500_000);
        host.write_telegram(&[0x02, 0x00, 0x01, 0x00, 0x31, 0x15, 0x12])
            .unwrap();
        let mut buf = [0u8; 16];
        let mut got = Vec::new();
        while got.len() < 7 {
            let n = sensor.read(&mut buf, Duration::from_millis(200)).unwrap();
            assert!(n > 0, "bytes did not arrive");
            got.extend_from_slice(&buf[..n]);
        }
        assert_eq!(got, [0x02, 0x00, 0x01, 0x00, 0x31, 0x15, 0x12]);
    }
}
