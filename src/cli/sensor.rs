//! Sensor subcommands: `probe`, `record`, `decode`, `emulate`.

use std::io::{BufWriter, Read, Write};
use std::ops::ControlFlow;
use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use clsmap::daemon::ros2_out::{LASER_FRAME, RECORDING_TOPIC};
use clsmap::files::tee::Tee;
use clsmap::input::bag::laser_scan;
use clsmap::input::lms200::{
    lms200_reach, lms200_scan_timing, note_mode, range_scan, scan_time_us, seconds,
};
use clsmap::ros2::bag::{BagTopic, BagWriter, Durability};
use clsmap::ros2::{ByteArray, LaserScan};
use lms200::driver::SerialDriver;
use lms200::link::{Event, LinkConfig};
use lms200::recording::{Record, RecordingReader};
use lms200::{Baud, DecodeEvent, Decoder, MeasuringMode, Reply, Scan, Units, Variant};
use serde::Serialize;
use std::sync::{Arc, Mutex};

use super::{DecodeFormat, UnitsArg};

/// Longest `probe` waits for a sensor: auto-baud over four speeds with
/// retries, plus the 3 s a mode change may take.
const PROBE_LIMIT: Duration = Duration::from_secs(30);

pub fn probe(port: &Path) -> anyhow::Result<ExitCode> {
    // Probing streams at the speed the sensor already supports everywhere
    // (38400) and with the units and mode it most likely has, so that a
    // sensor in its default configuration sees no EEPROM write.
    let config = LinkConfig {
        target_baud: Baud::B38400,
        real_time_indices: false,
        ..LinkConfig::default()
    };
    let mut driver = SerialDriver::open(port, config)
        .with_context(|| format!("cannot probe {}", port.display()))?;
    let start = Instant::now();
    let mut found = None;
    let mut errors = Vec::new();
    driver.run(
        || start.elapsed() > PROBE_LIMIT,
        |event| match event {
            Event::Connected {
                baud,
                variant,
                units,
                device_type,
                firmware,
            } => {
                found = Some((
                    *baud,
                    *variant,
                    *units,
                    device_type.clone(),
                    firmware.clone(),
                ));
                ControlFlow::Continue(())
            }
            Event::Scan(s) if found.is_some() => {
                let scan = &s.scan;
                println!("port:      {}", port.display());
                if let Some((baud, variant, units, device, firmware)) = &found {
                    println!("device:    {device} (firmware {firmware})");
                    println!("variant:   {}", variant_name(*variant));
                    println!("units:     {}", units_name(*units));
                    println!("streaming: {} Bd", baud.bits_per_second());
                }
                println!("scan:      {} values", scan.values.len());
                ControlFlow::Break(())
            }
            Event::Error(e) => {
                errors.push(e.to_string());
                ControlFlow::Continue(())
            }
            _ => ControlFlow::Continue(()),
        },
    )?;
    if found.is_none() {
        let why = errors.last().cloned().unwrap_or_else(|| "no answer".into());
        bail!(
            "no LMS200 found on {} within {} s: {why}",
            port.display(),
            PROBE_LIMIT.as_secs()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Where `record` writes.
pub struct RecordOutputs<'a> {
    pub recording: Option<&'a Path>,
    pub bag: Option<&'a Path>,
}

/// The recording's bytes as the driver writes them, shared with the bag
/// writer, which moves them into `/lms200/recording` messages.
#[derive(Clone, Default)]
struct SharedBytes(Arc<Mutex<Vec<u8>>>);

impl SharedBytes {
    fn take(&self) -> Vec<u8> {
        self.0
            .lock()
            .map(|mut b| std::mem::take(&mut *b))
            .unwrap_or_default()
    }
}

impl Write for SharedBytes {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0
            .lock()
            .map_err(|_| std::io::Error::other("recording buffer poisoned"))?
            .extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The bag `record --bag` writes, as the scans come.
struct RecordBag {
    writer: BagWriter,
    scan: BagTopic<LaserScan>,
    raw: BagTopic<ByteArray>,
    bytes: SharedBytes,
    /// Wall-clock time minus the monotonic clock, to stamp scans (s).
    clock_offset: f64,
    started: Instant,
    last_flush: Instant,
    mode: MeasuringMode,
}

impl RecordBag {
    fn create(path: &Path, mode: MeasuringMode) -> anyhow::Result<RecordBag> {
        let mut writer = BagWriter::create(path)?;
        let scan = writer.topic::<LaserScan>("/scan", Durability::Volatile)?;
        let raw = writer.topic::<ByteArray>(RECORDING_TOPIC, Durability::Volatile)?;
        let started = Instant::now();
        Ok(RecordBag {
            writer,
            scan,
            raw,
            bytes: SharedBytes::default(),
            clock_offset: seconds(lms200::driver::unix_micros()),
            started,
            last_flush: started,
            mode,
        })
    }

    fn now_ns(&self) -> u64 {
        let t = self.clock_offset + self.started.elapsed().as_secs_f64();
        (t * 1e9) as u64
    }

    /// Moves the recording bytes written since the last call into a
    /// message, then the scan (if any); the chunk is closed every second.
    fn on_event(&mut self, scan: Option<&lms200::link::TimedScan>) -> anyhow::Result<()> {
        self.drain()?;
        if let Some(ts) = scan {
            let since = ts
                .timestamp
                .saturating_duration_since(self.started)
                .as_secs_f64();
            let before = self
                .started
                .saturating_duration_since(ts.timestamp)
                .as_secs_f64();
            let t = self.clock_offset + since - before;
            if let Some(rs) = range_scan(&ts.scan, t, self.mode) {
                let (time_increment, scan_time) = lms200_scan_timing(rs.angle_increment);
                let reach = lms200_reach(ts.units);
                let msg = laser_scan(&rs, LASER_FRAME, reach, time_increment, scan_time);
                self.writer.write(&mut self.scan, (t * 1e9) as u64, &msg)?;
            }
        }
        if self.last_flush.elapsed() >= Duration::from_secs(1) {
            self.writer.flush()?;
            self.last_flush = Instant::now();
        }
        Ok(())
    }

    fn drain(&mut self) -> anyhow::Result<()> {
        let data = self.bytes.take();
        if !data.is_empty() {
            let ns = self.now_ns();
            self.writer.write(&mut self.raw, ns, &ByteArray { data })?;
        }
        Ok(())
    }

    fn finish(mut self) -> anyhow::Result<()> {
        self.drain()?;
        self.writer.finish()?;
        Ok(())
    }
}

pub fn record(
    port: &Path,
    outputs: &RecordOutputs<'_>,
    scans: Option<u64>,
    baud: u32,
    variant: &str,
    units: UnitsArg,
) -> anyhow::Result<ExitCode> {
    let baud = Baud::from_bits_per_second(baud)
        .with_context(|| format!("{baud} Bd: the LMS200 runs at 9600, 19200, 38400 or 500000"))?;
    let variant = parse_variant(variant)?;
    let units = match units {
        UnitsArg::Mm => Units::Mm,
        UnitsArg::Cm => Units::Cm,
    };
    let config = LinkConfig {
        variant,
        units,
        target_baud: baud,
        ..LinkConfig::default()
    };
    let note = format!(
        "lms200 variant={} units={} mode={:02x}",
        variant_name(variant),
        units_name(units),
        config.measuring_mode.code()
    );
    let mode = config.measuring_mode;
    // The port first: a wrong --port must not cost an existing file.
    let driver = SerialDriver::open(port, config)
        .with_context(|| format!("cannot open {}", port.display()))?;
    let mut sinks: Vec<Box<dyn Write + Send>> = Vec::new();
    let mut written = Vec::new();
    // The bag first: if it cannot be made, no empty recording is left
    // behind (it would block the retry, files are never overwritten).
    let mut bag = match outputs.bag {
        Some(path) => {
            let bag = RecordBag::create(path, mode)?;
            sinks.push(Box::new(bag.bytes.clone()));
            written.push(path.display().to_string());
            Some(bag)
        }
        None => None,
    };
    if let Some(out) = outputs.recording {
        // Never overwrite a recording: it may be the only copy of a run.
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(out)
            .with_context(|| {
                format!(
                    "cannot create the recording {} (an existing file is never overwritten)",
                    out.display()
                )
            })?;
        sinks.push(Box::new(BufWriter::new(file)));
        written.push(out.display().to_string());
    }
    let written = written.join(" and ");
    let mut driver = driver.with_recording(Box::new(Tee(sinks)), &note)?;
    let stop = super::stop_flag()?;
    let mut count = 0u64;
    let mut bag_error = None;
    driver.run(
        || stop.load(Ordering::SeqCst),
        |event| {
            match event {
                Event::Connected { baud, .. } => {
                    tracing::info!(
                        baud = baud.bits_per_second(),
                        "streaming, recording to {written}"
                    )
                }
                Event::Scan(_) => count += 1,
                Event::Error(e) => tracing::warn!("{e}"),
                Event::SensorSilent => tracing::warn!("sensor silent, re-initialising"),
                Event::SensorRestarted => tracing::warn!("sensor restarted, re-initialising"),
                _ => {}
            }
            if let Some(b) = bag.as_mut()
                && bag_error.is_none()
            {
                let scan = match event {
                    Event::Scan(ts) => Some(ts),
                    _ => None,
                };
                if let Err(e) = b.on_event(scan) {
                    bag_error = Some(e);
                    return ControlFlow::Break(());
                }
            }
            if scans.is_some_and(|n| count >= n) {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    )?;
    let stats = driver.stats();
    drop(driver);
    if let Some(e) = bag_error {
        return Err(e);
    }
    if let Some(b) = bag {
        b.finish()?;
    }
    eprintln!(
        "recorded {count} scans to {written}; dropped frames {}, lost telegrams {}, re-initialisations {}",
        stats.dropped_frames, stats.lost_telegrams, stats.reinits
    );
    Ok(ExitCode::SUCCESS)
}

/// One decoded scan as `decode` prints it.
#[derive(Debug, Serialize)]
struct DecodedScan {
    /// Mid-sweep time (s since the Unix epoch; byte offset order for raw dumps).
    t: f64,
    units: &'static str,
    /// Distance field of each value in `units`, as sent; special codes kept
    /// as their raw numbers.
    ranges: Vec<u16>,
    /// Flag bits of each value (the bits above the distance field).
    flags: Vec<u16>,
    status: u8,
    #[serde(skip_serializing_if = "Option::is_none")]
    scan_index: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    telegram_index: Option<u8>,
}

pub fn decode(
    file: &Path,
    raw: bool,
    format: DecodeFormat,
    mode_arg: Option<u8>,
) -> anyhow::Result<ExitCode> {
    let mut mode = match mode_arg {
        Some(code) => MeasuringMode::from_code(code)
            .with_context(|| format!("measuring mode {code:02x} is reserved"))?,
        None => MeasuringMode::Bits13FieldsAbDazzle,
    };
    let mut input =
        std::fs::File::open(file).with_context(|| format!("cannot open {}", file.display()))?;
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    if format == DecodeFormat::Csv {
        writeln!(out, "t,beam,units,range,flags,status")?;
    }
    let mut decoder = Decoder::new();
    let mut printed = 0u64;
    let mut emit = |scan: &Scan, status: u8, t: f64, mode: MeasuringMode| -> anyhow::Result<()> {
        let decoded = decoded_scan(scan, status, t, mode);
        match format {
            DecodeFormat::Jsonl => {
                serde_json::to_writer(&mut out, &decoded).map_err(std::io::Error::from)?;
                writeln!(out)?;
            }
            DecodeFormat::Csv => {
                for (i, (r, f)) in decoded.ranges.iter().zip(&decoded.flags).enumerate() {
                    writeln!(
                        out,
                        "{:.6},{i},{},{r},{f},{}",
                        decoded.t, decoded.units, decoded.status
                    )?;
                }
            }
        }
        printed += 1;
        Ok(())
    };
    let mut broke = None;
    let mut damaged = 0usize;
    if raw {
        // Streamed in chunks, so a dump of any size (or a device that never
        // ends) is decoded in constant memory.
        let mut chunk = vec![0u8; 64 * 1024];
        let mut scans = Vec::new();
        let mut number = 0usize;
        loop {
            let n = match input.read(&mut chunk) {
                Ok(0) => break,
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    return Err(anyhow::Error::new(e))
                        .with_context(|| format!("cannot read {}", file.display()));
                }
            };
            decoder.feed(&chunk[..n], |ev| collect_scan(ev, &mut scans));
            for (scan, status) in scans.drain(..) {
                // A raw dump has no clock: number the scans instead.
                emit(&scan, status, number as f64, mode)?;
                number += 1;
            }
        }
    } else {
        let reader = RecordingReader::new(std::io::BufReader::new(input))
            .with_context(|| format!("cannot read {}", file.display()))?;
        let mut baud = Baud::B9600;
        for record in reader {
            let record = match record {
                Ok(r) => r,
                // The reader skips a damaged stretch and goes on.
                Err(e @ lms200::recording::RecordingError::Damaged { .. }) => {
                    eprintln!("{}: {e}", file.display());
                    damaged += 1;
                    continue;
                }
                Err(e) => {
                    broke = Some(e);
                    break;
                }
            };
            match record {
                Record::Note { text, .. } if mode_arg.is_none() => {
                    if let Some(m) = note_mode(&text) {
                        mode = m;
                    }
                }
                Record::Baud { baud: bps, .. } => {
                    if let Some(b) = Baud::from_bits_per_second(bps) {
                        baud = b;
                    }
                }
                Record::Rx { t_us, bytes } => {
                    let mut scans = Vec::new();
                    decoder.feed(&bytes, |ev| collect_scan(ev, &mut scans));
                    for (scan, status) in scans {
                        let t = seconds(scan_time_us(t_us, &scan, baud));
                        emit(&scan, status, t, mode)?;
                    }
                }
                _ => {}
            }
        }
    }
    out.flush()?;
    let stats = decoder.stats();
    eprintln!(
        "{printed} scans; {} frames dropped (bad checksum {}, impossible length {}, implausible {}, truncated {}), {} junk bytes",
        stats.bad_crc
            + stats.impossible_length
            + stats.length_mismatch
            + stats.implausible
            + stats.truncated,
        stats.bad_crc,
        stats.impossible_length,
        stats.implausible,
        stats.truncated,
        stats.junk_bytes
    );
    if damaged > 0 && broke.is_none() {
        anyhow::bail!(
            "{}: {damaged} damaged stretches skipped (named above); the scans around them were printed",
            file.display()
        );
    }
    if let Some(e) = broke {
        // Everything before the break was printed; say where it broke.
        return Err(anyhow::Error::new(e).context(format!(
            "{}: decoded {printed} scans before the recording broke",
            file.display()
        )));
    }
    Ok(ExitCode::SUCCESS)
}

fn collect_scan(ev: DecodeEvent, scans: &mut Vec<(Scan, u8)>) {
    if let DecodeEvent::Reply(frame) = ev
        && let Reply::ScanData(scan) = frame.reply
    {
        scans.push((scan, frame.status.0));
    }
}

fn decoded_scan(scan: &Scan, status: u8, t: f64, mode: MeasuringMode) -> DecodedScan {
    let mask = mode.distance_mask();
    DecodedScan {
        t,
        units: scan.units().map(units_name).unwrap_or("reserved"),
        ranges: scan.values.iter().map(|v| v & mask).collect(),
        flags: scan
            .values
            .iter()
            .map(|v| v.checked_shr(mode.distance_bits()).unwrap_or(0))
            .collect(),
        status,
        scan_index: scan.indices.map(|i| i.scan),
        telegram_index: scan.indices.map(|i| i.telegram),
    }
}

pub fn parse_variant(s: &str) -> anyhow::Result<Variant> {
    Variant::ALL
        .into_iter()
        .find(|v| variant_name(*v) == s.trim())
        .with_context(|| {
            let names: Vec<String> = Variant::ALL.into_iter().map(variant_name).collect();
            format!("variant `{s}`: the LMS200 offers {}", names.join(", "))
        })
}

fn variant_name(v: Variant) -> String {
    format!(
        "{}/{}",
        v.fov_deg(),
        f64::from(v.resolution_centideg()) / 100.0
    )
}

fn units_name(u: Units) -> &'static str {
    match u {
        Units::Mm => "mm",
        Units::Cm => "cm",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variants_parse_by_name() {
        assert_eq!(parse_variant("180/0.5").unwrap(), Variant::Fov180Res50);
        assert_eq!(parse_variant("100/0.25").unwrap(), Variant::Fov100Res25);
        let err = parse_variant("270/0.5").unwrap_err().to_string();
        assert!(err.contains("180/0.5") && err.contains("100/1"), "{err}");
    }
}
