//! The emulator over a pseudo-terminal, driven through the CLI.

use super::*;

/// A running `clsmap emulate`; killed if the test ends without stopping it.
struct EmulatorProcess {
    child: Child,
    stdout: PathBuf,
    stderr: PathBuf,
}

impl EmulatorProcess {
    fn start(dir: &TempDir, link: &Path) -> EmulatorProcess {
        let (stdout, stderr) = (dir.join("emulator.out"), dir.join("emulator.err"));
        let child = clsmap_command()
            .arg("emulate")
            .arg("--link")
            .arg(link)
            .stdin(Stdio::null())
            .stdout(File::create(&stdout).unwrap())
            .stderr(File::create(&stderr).unwrap())
            .spawn()
            .unwrap();
        let mut emulator = EmulatorProcess {
            child,
            stdout,
            stderr,
        };
        let deadline = Instant::now() + EMULATOR_START_LIMIT;
        while !link.exists() {
            if let Some(status) = emulator.child.try_wait().unwrap() {
                panic!("the emulator exited ({status}):\n{}", emulator.output());
            }
            assert!(
                Instant::now() < deadline,
                "no link {} after {EMULATOR_START_LIMIT:?}:\n{}",
                link.display(),
                emulator.output()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        emulator
    }

    fn output(&self) -> String {
        let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();
        format!(
            "--- emulator stdout ---\n{}--- emulator stderr ---\n{}",
            read(&self.stdout),
            read(&self.stderr)
        )
    }

    /// Sends SIGINT (Ctrl-C) and waits for the exit.
    fn interrupt(&mut self) -> ExitStatus {
        let pid = self.child.id().to_string();
        let kill = Command::new("kill").args(["-INT", &pid]).status().unwrap();
        assert!(kill.success(), "kill -INT {pid} failed");
        wait_at_most(&mut self.child, EMULATOR_STOP_LIMIT).unwrap_or_else(|| {
            panic!(
                "the emulator ignored SIGINT for {EMULATOR_STOP_LIMIT:?}:\n{}",
                self.output()
            )
        })
    }
}

impl Drop for EmulatorProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[test]
fn probe_record_and_decode_against_the_emulator_then_stop_it_with_ctrl_c() {
    let dir = TempDir::new("emulator");
    let link = dir.join("lms200");
    let mut emulator = EmulatorProcess::start(&dir, &link);

    let probe = clsmap(&["probe", "--port", arg(&link)]).succeeded();
    assert!(probe.stdout.contains("LMS200"), "{probe}");
    assert!(probe.stdout.contains("180/0.5"), "{probe}");

    let recording = dir.join("x.rec");
    let record = clsmap(&[
        "record",
        "--port",
        arg(&link),
        "--out",
        arg(&recording),
        "--scans",
        "10",
    ])
    .succeeded();
    assert!(record.stderr.contains("recorded 10 scans"), "{record}");

    let decode = clsmap(&["decode", arg(&recording)]).succeeded();
    let scans = parse_jsonl(&decode.stdout);
    assert!(scans.len() >= 10, "{decode}");
    assert!(
        scans
            .iter()
            .all(|s| s.ranges.len() == BEAMS && s.units == "mm")
    );

    let status = emulator.interrupt();
    assert!(
        status.success(),
        "emulator exit {status}:\n{}",
        emulator.output()
    );
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "the emulator left its link {} behind",
        link.display()
    );
}
