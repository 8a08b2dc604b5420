//! The live view's HTTP server (axum), on a thread and a runtime of its
//! own: `/` the page (embedded, works offline), `/api/status`,
//! `/api/map` (the map file, version 2), `/api/geometry` (what the page
//! draws), `/api/trajectory`, `/api/events` (server-sent events: `status`
//! at the configured rate, `map` when the map changed), and, only with a
//! token, `POST /api/control/{pause,resume,stop}` and
//! `POST /api/control/pose?x=…&y=…&theta=…` (m, m, rad in the map frame:
//! where to look for the robot in a loaded map).
//!
//! Read-only without a token. At most `max_clients` requests at once,
//! streams included; more are refused with 503, never queued. One request
//! per connection and at most `2 · max_clients + 4` connections open (more
//! wait in the kernel's backlog), so clients cannot use up the daemon's
//! file descriptors. A stream sends only the newest snapshot, and a client
//! that leaves it unread for [`STALLED_CLIENT`] is dropped.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{Path, RawQuery, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};

use axum::routing::{get, post};
use tokio::sync::{Semaphore, mpsc, watch};
use tracing::{error, info};

use super::{ControlCommand, LiveView, MapView};
use crate::geometry::Pose2;

/// The page: one file, no outside resources.
const PAGE: &str = include_str!("page.html");

/// Why the server could not start.
#[derive(Debug, thiserror::Error)]
pub enum WebError {
    #[error("cannot listen on {address} for the live view")]
    Bind {
        address: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot start the live view's thread")]
    Thread(#[source] std::io::Error),
}

/// How the server runs.
#[derive(Debug, Clone)]
pub struct WebOptions {
    pub address: SocketAddr,
    /// Control requests need `Authorization: Bearer <token>`; none: no
    /// control at all.
    pub token: Option<String>,
    pub max_clients: usize,
}

/// Where the loop puts its snapshots, and takes the page's commands from.
#[derive(Debug)]
pub struct WebFeed {
    pub view: watch::Sender<Option<Arc<LiveView>>>,
    pub map: watch::Sender<Option<Arc<MapView>>>,
    pub control: mpsc::Receiver<ControlCommand>,
}

/// A running server; dropping it stops it.
#[derive(Debug)]
pub struct WebServer {
    address: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl WebServer {
    /// The address it listens on (the port filled in when 0 was asked).
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Stops serving and waits for the thread.
    pub fn stop(mut self) {
        self.shut_down();
    }

    fn shut_down(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            error!("the live view's thread panicked");
        }
    }
}

impl Drop for WebServer {
    fn drop(&mut self) {
        self.shut_down();
    }
}

#[derive(Clone)]
struct AppState {
    view: watch::Receiver<Option<Arc<LiveView>>>,
    map: watch::Receiver<Option<Arc<MapView>>>,
    control: mpsc::Sender<ControlCommand>,
    token: Option<Arc<str>>,
    clients: Arc<Semaphore>,
}

/// Binds `options.address` now (so a taken port is an error at start)
/// and serves on a thread of its own until stopped.
pub fn serve(options: WebOptions) -> Result<(WebServer, WebFeed), WebError> {
    let listener =
        std::net::TcpListener::bind(options.address).map_err(|source| WebError::Bind {
            address: options.address,
            source,
        })?;
    let bind_error = |source| WebError::Bind {
        address: options.address,
        source,
    };
    listener.set_nonblocking(true).map_err(bind_error)?;
    let address = listener.local_addr().map_err(bind_error)?;
    let (view_tx, view_rx) = watch::channel(None);
    let (map_tx, map_rx) = watch::channel(None);
    let (control_tx, control_rx) = mpsc::channel(8);
    let state = AppState {
        view: view_rx,
        map: map_rx,
        control: control_tx,
        token: options.token.as_deref().map(Arc::from),
        clients: Arc::new(Semaphore::new(options.max_clients)),
    };
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let thread = std::thread::Builder::new()
        .name("clsmap-web".into())
        .spawn(move || {
            let runtime = match tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            {
                Ok(rt) => rt,
                Err(e) => {
                    error!("cannot start the live view's runtime: {e}");
                    return;
                }
            };
            runtime.block_on(async move {
                let listener = match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => l,
                    Err(e) => {
                        error!("cannot listen for the live view: {e}");
                        return;
                    }
                };
                // Requests beyond `max_clients` get 503 from the router;
                // connections beyond this wait in the backlog.
                let connections = 2 * options.max_clients + 4;
                tokio::select! {
                    () = accept_loop(listener, router(state), connections) => {}
                    _ = stop_rx => {}
                }
            });
        })
        .map_err(WebError::Thread)?;
    info!(%address, "live view on http://{address}/");
    Ok((
        WebServer {
            address,
            stop: Some(stop_tx),
            thread: Some(thread),
        },
        WebFeed {
            view: view_tx,
            map: map_tx,
            control: control_rx,
        },
    ))
}

/// How long a client may leave written data unread before it is dropped:
/// a page that stopped reading (a laptop lid closed) gives back its slot.
pub const STALLED_CLIENT: Duration = Duration::from_secs(10);

/// Serves each connection on its own task, its writes guarded by
/// [`StallGuard`], one request per connection (no keep-alive, so an idle
/// connection does not outlive its request), at most `connections` at
/// once (more wait in the kernel's backlog); a failed accept (out of
/// descriptors) waits a moment.
async fn accept_loop(listener: tokio::net::TcpListener, router: Router, connections: usize) {
    let open = Arc::new(Semaphore::new(connections));
    loop {
        let Ok(slot) = open.clone().acquire_owned().await else {
            return;
        };
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            Err(e) => {
                error!("the live view cannot accept a connection: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        let service = hyper_util::service::TowerToHyperService::new(router.clone());
        let io = hyper_util::rt::TokioIo::new(StallGuard::new(stream, STALLED_CLIENT));
        tokio::spawn(async move {
            let _slot = slot;
            let served = hyper::server::conn::http1::Builder::new()
                .timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(Duration::from_secs(10))
                .keep_alive(false)
                .serve_connection(io, service)
                .await;
            if let Err(e) = served {
                tracing::debug!("live view connection ended: {e}");
            }
        });
    }
}

/// A socket whose writes fail once they have waited `limit` for the peer
/// to read, so a stalled client's connection ends instead of holding its
/// slot (and its task) for ever.
struct StallGuard {
    inner: tokio::net::TcpStream,
    limit: Duration,
    deadline: Option<std::pin::Pin<Box<tokio::time::Sleep>>>,
}

impl StallGuard {
    fn new(inner: tokio::net::TcpStream, limit: Duration) -> StallGuard {
        StallGuard {
            inner,
            limit,
            deadline: None,
        }
    }

    /// Pending: arm the deadline (or see it passed); ready: disarm it.
    fn guard<T>(
        &mut self,
        cx: &mut std::task::Context<'_>,
        polled: std::task::Poll<std::io::Result<T>>,
    ) -> std::task::Poll<std::io::Result<T>> {
        use std::task::Poll;
        if polled.is_ready() {
            self.deadline = None;
            return polled;
        }
        let limit = self.limit;
        let deadline = self
            .deadline
            .get_or_insert_with(|| Box::pin(tokio::time::sleep(limit)));
        match deadline.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                "the client stopped reading",
            ))),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl tokio::io::AsyncRead for StallGuard {
    fn poll_read(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl tokio::io::AsyncWrite for StallGuard {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        let polled = std::pin::Pin::new(&mut self.inner).poll_write(cx, buf);
        self.guard(cx, polled)
    }

    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        let polled = std::pin::Pin::new(&mut self.inner).poll_flush(cx);
        self.guard(cx, polled)
    }

    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

fn router(state: AppState) -> Router {
    let limited = Router::new()
        .route("/", get(page))
        .route("/api/status", get(status))
        .route("/api/map", get(map_file))
        .route("/api/geometry", get(geometry))
        .route("/api/trajectory", get(trajectory))
        .route("/api/control/{action}", post(control))
        .layer(middleware::from_fn_with_state(state.clone(), one_of_few));
    Router::new()
        // The stream takes its client slot itself and keeps it.
        .route("/api/events", get(events))
        .merge(limited)
        .with_state(state)
}

fn too_many() -> Response {
    (
        StatusCode::SERVICE_UNAVAILABLE,
        [(header::RETRY_AFTER, HeaderValue::from_static("2"))],
        "too many clients of the live view; try again\n",
    )
        .into_response()
}

/// Serves a request only while fewer than `max_clients` are in progress.
async fn one_of_few(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let Ok(_permit) = state.clients.clone().try_acquire_owned() else {
        return too_many();
    };
    next.run(request).await
}

/// The page, with the newest snapshots in it so that it shows the robot
/// at once (and a browser that runs no script past the first one still
/// sees the map).
async fn page(State(state): State<AppState>) -> Response {
    #[derive(serde::Serialize)]
    struct Initial<'a> {
        view: Option<&'a LiveView>,
        map: Option<&'a MapView>,
    }
    let (view, map) = (state.view.borrow().clone(), state.map.borrow().clone());
    let initial = Initial {
        view: view.as_deref(),
        map: map.as_deref(),
    };
    // JSON inside <script>: no `<`, `>` or `&` may appear raw (they could
    // end the element or open a comment); JSON's \u escapes stand for them.
    let json = serde_json::to_string(&initial)
        .unwrap_or_else(|_| "{}".into())
        .replace('<', "\\u003c")
        .replace('>', "\\u003e")
        .replace('&', "\\u0026");
    (
        [
            // Not to be framed by another site (a STOP button under a
            // decoy), and nothing loaded from elsewhere.
            (header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY")),
            (
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static(
                    "default-src 'self'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; frame-ancestors 'none'",
                ),
            ),
        ],
        Html(PAGE.replace("/*INITIAL*/", &json)),
    )
        .into_response()
}

fn json(body: String) -> Response {
    (
        [
            (
                header::CONTENT_TYPE,
                HeaderValue::from_static("application/json"),
            ),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-store")),
        ],
        body,
    )
        .into_response()
}

fn not_yet(what: &str) -> Response {
    (
        StatusCode::SERVICE_UNAVAILABLE,
        format!("no {what} yet: the loop has not published one\n"),
    )
        .into_response()
}

fn encode<T: serde::Serialize>(value: &T) -> Response {
    match serde_json::to_string(value) {
        Ok(body) => json(body),
        Err(e) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("cannot encode: {e}\n"),
        )
            .into_response(),
    }
}

async fn status(State(state): State<AppState>) -> Response {
    let view = state.view.borrow().clone();
    match view {
        Some(view) => encode(&*view),
        None => not_yet("status"),
    }
}

async fn geometry(State(state): State<AppState>) -> Response {
    let map = state.map.borrow().clone();
    match map {
        Some(map) => encode(&*map),
        None => not_yet("map"),
    }
}

async fn trajectory(State(state): State<AppState>) -> Response {
    let map = state.map.borrow().clone();
    match map {
        Some(map) => encode(&map.path),
        None => not_yet("trajectory"),
    }
}

/// The map file as `clsmap map` writes it (version 2), encoded here on
/// the server's thread.
async fn map_file(State(state): State<AppState>) -> Response {
    let contents = state.map.borrow().as_ref().and_then(|m| m.contents.clone());
    let Some(contents) = contents else {
        return not_yet("map");
    };
    let encoded = tokio::task::spawn_blocking(move || crate::map::file::encode(&contents)).await;
    match encoded {
        Ok(Ok(body)) => json(body),
        Ok(Err(e)) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("cannot encode the map: {e}\n"),
        )
            .into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{e}\n")).into_response(),
    }
}

/// Whether `headers` carry the configured token (compared in constant
/// time, so its length and content do not leak through timing).
fn authorized(token: &str, headers: &HeaderMap) -> bool {
    let Some(given) = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
    else {
        return false;
    };
    let (a, b) = (given.as_bytes(), token.as_bytes());
    let differ = a
        .iter()
        .zip(b)
        .fold(a.len() ^ b.len(), |acc, (x, y)| acc | usize::from(x ^ y));
    differ == 0
}

async fn control(
    State(state): State<AppState>,
    Path(action): Path<String>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
) -> Response {
    let Some(token) = state.token.as_deref() else {
        return (
            StatusCode::FORBIDDEN,
            "this live view is read-only (no [web] token configured)\n",
        )
            .into_response();
    };
    if !authorized(token, &headers) {
        return (
            StatusCode::UNAUTHORIZED,
            [(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"))],
            "a control request needs the configured token\n",
        )
            .into_response();
    }
    let command = match action.as_str() {
        "pause" => ControlCommand::Pause,
        "resume" => ControlCommand::Resume,
        "stop" => ControlCommand::Stop,
        "pose" => match pose_of_query(query.as_deref().unwrap_or("")) {
            Ok(pose) => ControlCommand::Pose(pose),
            Err(why) => return (StatusCode::BAD_REQUEST, format!("{why}\n")).into_response(),
        },
        _ => {
            return (
                StatusCode::NOT_FOUND,
                "control actions: pause, resume, stop, pose?x=…&y=…&theta=…\n",
            )
                .into_response();
        }
    };
    match state.control.try_send(command) {
        Ok(()) => (
            StatusCode::ACCEPTED,
            format!("{action}: sent to the loop\n"),
        )
            .into_response(),
        Err(_) => too_many(),
    }
}

/// The pose of `x=…&y=…&theta=…` (m, m, rad; each once, finite).
fn pose_of_query(query: &str) -> Result<Pose2, String> {
    let mut v = [None; 3];
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
        let slot = match key {
            "x" => &mut v[0],
            "y" => &mut v[1],
            "theta" => &mut v[2],
            other => return Err(format!("pose: unknown parameter {:?}", truncate(other))),
        };
        let number = value
            .parse::<f64>()
            .ok()
            .filter(|n| n.is_finite())
            .ok_or_else(|| format!("pose: {key} is not a finite number: {:?}", truncate(value)))?;
        if slot.replace(number).is_some() {
            return Err(format!("pose: {key} given twice"));
        }
    }
    match v {
        [Some(x), Some(y), Some(theta)] => Ok(Pose2::new(x, y, theta)),
        _ => Err("pose: x, y and theta are needed (m, m, rad in the map frame)".into()),
    }
}

/// At most 32 characters of what a client sent, for an error message.
fn truncate(s: &str) -> String {
    s.chars().take(32).collect()
}

/// Server-sent events: `status` with each new view, `map` with each new
/// map version (its geometry), the newest only.
async fn events(State(state): State<AppState>) -> Response {
    let Ok(permit) = state.clients.clone().try_acquire_owned() else {
        return too_many();
    };
    let mut view = state.view.clone();
    let mut map = state.map.clone();
    // The first events give what is there now.
    view.mark_changed();
    map.mark_changed();
    let stream = futures_util::stream::unfold(
        (view, map, permit),
        |(mut view, mut map, permit)| async move {
            let event = tokio::select! {
                changed = map.changed() => {
                    changed.ok()?;
                    let m = map.borrow_and_update().clone();
                    m.and_then(|m| serde_json::to_string(&*m).ok()).map(|d| Event::default().event("map").data(d))
                }
                changed = view.changed() => {
                    changed.ok()?;
                    let v = view.borrow_and_update().clone();
                    v.and_then(|v| serde_json::to_string(&*v).ok()).map(|d| Event::default().event("status").data(d))
                }
            };
            let event = event.unwrap_or_else(|| Event::default().comment("nothing yet"));
            Some((
                Ok::<_, std::convert::Infallible>(event),
                (view, map, permit),
            ))
        },
    );
    Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(Duration::from_secs(10)))
        .into_response()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use tokio::io::AsyncWriteExt;

    #[test]
    fn a_client_that_stops_reading_is_dropped() {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        runtime.block_on(async {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            let address = listener.local_addr().unwrap();
            // The client connects and never reads.
            let _client = tokio::net::TcpStream::connect(address).await.unwrap();
            let (server_side, _) = listener.accept().await.unwrap();
            let mut guarded = StallGuard::new(server_side, Duration::from_millis(300));
            let chunk = vec![0u8; 64 * 1024];
            let started = std::time::Instant::now();
            let mut written = 0usize;
            let error = loop {
                match guarded.write(&chunk).await {
                    Ok(n) => written += n,
                    Err(e) => break e,
                }
                assert!(
                    written < 1 << 30,
                    "1 GiB written to a client that never reads"
                );
            };
            assert_eq!(error.kind(), std::io::ErrorKind::TimedOut);
            // Dropped once the buffers were full and the limit had passed.
            assert!(started.elapsed() >= Duration::from_millis(300));
            assert!(written > 0);
        });
    }

    #[test]
    fn the_token_is_compared_whole() {
        let mut headers = HeaderMap::new();
        let token = "0123456789abcdef";
        assert!(!authorized(token, &headers));
        headers.insert(
            header::AUTHORIZATION,
            HeaderValue::from_static("Bearer 0123456789abcdef"),
        );
        assert!(authorized(token, &headers));
        headers.insert(
            header::AUTHORIZATION,
            HeaderValue::from_static("Bearer 0123456789abcde"),
        );
        assert!(!authorized(token, &headers));
        headers.insert(
            header::AUTHORIZATION,
            HeaderValue::from_static("Bearer 0123456789abcdef0"),
        );
        assert!(!authorized(token, &headers));
        headers.insert(
            header::AUTHORIZATION,
            HeaderValue::from_static("0123456789abcdef"),
        );
        assert!(!authorized(token, &headers));
    }

    #[test]
    fn a_pose_is_read_from_its_query_or_refused_with_the_reason() {
        let p = pose_of_query("x=1.5&y=-2&theta=0.25").unwrap();
        assert_eq!((p.x, p.y, p.theta), (1.5, -2.0, 0.25));
        let p = pose_of_query("theta=3&y=2&x=1").unwrap();
        assert_eq!((p.x, p.y, p.theta), (1.0, 2.0, 3.0));
        for (query, why) in [
            ("", "are needed"),
            ("x=1&y=2", "are needed"),
            ("x=1&y=2&theta=nan", "theta is not a finite number"),
            ("x=1&y=2&theta=inf", "theta is not a finite number"),
            ("x=1&y=2&theta", "theta is not a finite number"),
            ("x=1&x=2&y=2&theta=0", "x given twice"),
            ("x=1&y=2&theta=0&z=4", "unknown parameter \"z\""),
        ] {
            let error = pose_of_query(query).unwrap_err();
            assert!(error.contains(why), "{query}: {error}");
        }
    }
}
