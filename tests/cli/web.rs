//! The live view in a real browser (Debian's headless Chromium) against
//! `clsmap run` and `clsmap view`. Real time: run with `--ignored` (CI
//! does, after installing chromium).

use super::daemon::{Daemon, demo_run_config};
use super::*;

/// Debian's chromium, headless, as this machine allows it.
fn chromium(profile: &Path) -> Command {
    let path = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .find(|p| Path::new(p).exists())
        .expect("the browser tests need Debian's chromium (apt-get install chromium)");
    let mut c = Command::new(path);
    c.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
    ])
    .arg(format!("--user-data-dir={}", profile.display()))
    .stdin(Stdio::null())
    .stderr(Stdio::null());
    c
}

/// The page's DOM once its scripts have drawn the snapshot it came with.
fn dom(profile: &Path, url: &str) -> String {
    let out = chromium(profile)
        .args(["--dump-dom", url])
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The text of the element `id` in `dom`.
fn text_of<'a>(dom: &'a str, id: &str) -> &'a str {
    let at = dom
        .find(&format!("id=\"{id}\""))
        .unwrap_or_else(|| panic!("no #{id} in the page"));
    let rest = &dom[at..];
    let start = rest.find('>').map_or(rest.len(), |i| i + 1);
    let end = rest[start..].find('<').map_or(rest.len(), |i| start + i);
    &rest[start..end]
}

/// Polls `f` every 200 ms until it gives `Some`, at most `limit`.
fn within<T>(limit: Duration, what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + limit;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(Instant::now() < deadline, "{what} not within {limit:?}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
#[ignore = "real time and a browser; CI runs it: cargo test --test cli -- --ignored"]
fn the_page_shows_clsmap_run_mapping_in_a_headless_browser() {
    let dir = TempDir::new("web-run");
    let config = demo_run_config(&dir, "");
    let mut daemon = Daemon::start(&config);
    daemon.wait_for("live view on http://", Duration::from_secs(60));
    let line = daemon
        .line_with("live view on http://")
        .unwrap()
        .to_string();
    let address = line
        .rsplit("http://")
        .next()
        .and_then(|a| a.split('/').next())
        .unwrap()
        .to_string();
    let url = format!("http://{address}/");
    let profile = dir.join("chromium");
    // The map has walls and the robot is drawn.
    let first = within(Duration::from_secs(60), "walls on the page", || {
        let d = dom(&profile, &url);
        (d.matches("class=\"wall\"").count() > 5 && text_of(&d, "scans") != "–").then_some(d)
    });
    assert!(
        first.contains("id=\"robot\" visibility=\"visible\""),
        "no robot marker"
    );
    assert_eq!(text_of(&first, "sensor"), "streaming");
    assert_eq!(text_of(&first, "state"), "localized");
    for field in ["state", "pose", "sensor", "rate", "mapsize", "uptime"] {
        let t = text_of(&first, field);
        assert!(!t.is_empty() && t != "–", "#{field} is empty: {t:?}");
    }
    // The panel follows the robot.
    let scans = text_of(&first, "scans").to_string();
    within(Duration::from_secs(20), "the panel changing", || {
        let d = dom(&profile, &url);
        (text_of(&d, "scans") != scans).then_some(())
    });
    // A picture of it for the CI run's artifacts.
    let artifacts = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/ci-artifacts");
    std::fs::create_dir_all(&artifacts).unwrap();
    let shot = artifacts.join("live-view.png");
    let _ = std::fs::remove_file(&shot);
    chromium(&profile)
        .args(["--window-size=1200,760"])
        .arg(format!("--screenshot={}", shot.display()))
        .arg(&url)
        .status()
        .unwrap();
    assert!(shot.is_file(), "no screenshot");
    daemon.signal("TERM");
    let (status, _, stderr) = daemon.finish(Duration::from_secs(30));
    assert!(status.success(), "{status}\n{stderr}");
}

#[test]
#[ignore = "a browser; CI runs it: cargo test --test cli -- --ignored"]
fn the_page_shows_a_saved_map_from_clsmap_view() {
    let dir = TempDir::new("web-view");
    let out = dir.join("out");
    map(&fixture(CSAIL_FIXTURE), &out, &[]).succeeded();
    let map_json = out.join("map.json");
    let walls = clsmap::map::file::load(&map_json)
        .unwrap()
        .contents
        .cls
        .actual_segments()
        .count();
    let mut child = clsmap_command()
        .args(["view", arg(&map_json), "--bind", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let address = line
        .split("http://")
        .nth(1)
        .unwrap()
        .split('/')
        .next()
        .unwrap();
    let d = dom(&dir.join("chromium"), &format!("http://{address}/"));
    let _ = child.kill();
    let _ = child.wait();
    assert_eq!(d.matches("class=\"wall\"").count(), walls, "walls drawn");
    assert!(
        text_of(&d, "sensor").starts_with("saved map"),
        "{}",
        text_of(&d, "sensor")
    );
    assert!(text_of(&d, "mapsize").starts_with(&walls.to_string()));
}
